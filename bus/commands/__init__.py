"""Commands to robots: requests shaped from what a surface sends, validated by the
robot's owner, answered with a reply.

    from sonibus.bus import commands

    commands.from_words("say", ["hello", "volume=0.5"])   # the command line
    commands.from_osc("say", ["hello", 0.5])               # an OSC message's arguments
    commands.from_json("say", {"text": "hello", "volume": 0.5})   # a browser's JSON
    # each gives {'text': 'hello', 'volume': 0.5}, or raises CommandError("bad_request")
    # with the same message for the same mistake

    commands.validate("say", request, model)   # at the owner: ranges, joints, postures
    commands.ok_reply("say", {"duration": 1.2})
"""

from .shape import Argument, from_json, from_osc, from_words, signature
from .validate import (
    LIMIT_TOLERANCE,
    Command,
    error_reply,
    expand_stiffness_names,
    ok_reply,
    request_args,
    validate,
    verbs,
)

__all__ = [
    "LIMIT_TOLERANCE", "Argument", "Command", "error_reply", "expand_stiffness_names", "from_json", "from_osc",
    "from_words", "ok_reply", "request_args", "signature", "validate", "verbs",
]
