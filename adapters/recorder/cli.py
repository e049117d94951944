"""The recording subcommands: ``sonibus record``, ``replay``, ``info``, ``recover``,
``export`` and ``plot`` (registered in the ``sonibus.commands`` entry-point group)."""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import threading
import time
from collections.abc import Callable

from sonibus.bus import keys, runner
from sonibus.bus.cli import robot as live_robot
from sonibus.bus.cli.api import Command, Environment, Exit, bus_config
from sonibus.bus.cli.hints import reach_hint
from sonibus.bus.errors import ConfigError
from sonibus.bus.node import Bus
from sonibus.bus.session import links

from .export import export_csv
from .plot import plot
from .reading import Recording, RecordingError, StillRecording, head
from .recorder import EVERYTHING, MICROPHONES, Recorder, RecorderConfig, describe
from .repair import recover
from .replay import Replay, ReplayConfig
from .wav import audio_keys, export_wav

log = logging.getLogger(__name__)


def _said(problems: str) -> None:
    """What a command skipped in a recording (``Recording.problems``), as a warning."""
    if problems:
        log.warning(problems)


def _while_running(env: Environment, line: Callable[[], str], done: Callable[[], bool] = lambda: False,
                   every_s: float = 1.0) -> threading.Thread:
    """A thread that shows ``line()`` on stderr (rewritten in place on a terminal)
    until ``env.stop``; it sets ``env.stop`` itself once ``done()``."""
    tty = env.stderr.isatty()

    def show() -> None:
        last = 0.0
        while not env.stop.wait(0.25):
            if done():
                env.stop.set()
            elif time.monotonic() - last >= (0.25 if tty else every_s):
                last = time.monotonic()
                print(("\r\033[K" if tty else "") + line(), end="" if tty else "\n", file=env.stderr, flush=True)
        if tty:
            print(file=env.stderr)

    thread = threading.Thread(target=show, name="status", daemon=True)
    thread.start()
    return thread


def _run(adapter: Recorder | Replay, args: argparse.Namespace, env: Environment,
         line: Callable[[], str], done: Callable[[], bool] = lambda: False, every_s: float = 1.0,
         on_bus: Callable[[Bus], None] = lambda bus: None) -> None:
    """Run ``adapter`` with a status line until it is ``done()`` or stopped; Ctrl-C
    and SIGTERM are the normal way to end it (the caller reports what was done)."""
    status: list[threading.Thread] = []

    def started(bus: Bus) -> None:
        on_bus(bus)
        status.append(_while_running(env, line, done, every_s))

    try:
        runner.run([adapter], bus_config(args), env.stop, on_started=started)
    except KeyboardInterrupt:
        pass
    finally:
        env.stop.set()
        for thread in status:
            thread.join(2.0)


# -- record -------------------------------------------------------------------------


def _record_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.mcap")
    p.add_argument("keyexpr", nargs="*", metavar="KEYEXPR",
                   help=f"what to record (default: {' '.join(EVERYTHING)}: joints, derived values and events of "
                        "every robot, and each robot's info; no audio: microphones only when named, e.g. "
                        f"'{MICROPHONES}')")
    p.add_argument("--overwrite", "--force", dest="overwrite", action="store_true",
                   help="overwrite FILE if it exists (the recorder node's overwrite = true)")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument("--rotate-s", type=float, default=0.0, metavar="S",
                   help="a new file every S seconds (FILE needs {time}, e.g. show-{time}.mcap)")
    p.add_argument("--rotate-mb", type=float, default=0.0, metavar="MB",
                   help="a new file once one holds MB megabytes (FILE needs {time})")
    p.add_argument("--min-free-mb", type=float, default=RecorderConfig.min_free_mb, metavar="MB",
                   help="stop, the file finished, when the disk has less free (default: %(default)g; 0: never)")
    p.add_argument("--per-joint-keys", action="store_true",
                   help="record joint keys as published, not from frames (for publishers that put no frames)")
    p.add_argument("--no-foxglove", dest="foxglove", action="store_false",
                   help="leave out the channels Foxglove's panels read (frames whole, events as logs, arm transforms)")
    p.add_argument("--status-every", type=float, default=5.0, metavar="S",
                   help="seconds between status lines when not on a terminal (default: 5)")


def _record(args: argparse.Namespace, env: Environment) -> Exit:
    options = {"subscribe": tuple(args.keyexpr)} if args.keyexpr else {}
    flags = {"rotate_s": "--rotate-s", "rotate_mb": "--rotate-mb", "min_free_mb": "--min-free-mb"}
    try:
        config = RecorderConfig(path=args.file, overwrite=args.overwrite, status_every_s=0,
                                per_joint_keys=args.per_joint_keys, foxglove=args.foxglove, rotate_s=args.rotate_s,
                                rotate_mb=args.rotate_mb, min_free_mb=args.min_free_mb,
                                warn_free_mb=max(RecorderConfig.warn_free_mb, args.min_free_mb), **options)
    except ConfigError as exc:  # named as the node would be at start, or by its flag
        key, _, problem = str(exc).removeprefix("key '").partition("': ")
        raise ConfigError(f"{flags[key]} {problem}" if key in flags else f"node 'record': {exc}") from None
    recorder = Recorder(config, name="record")
    deadline = time.monotonic() + args.duration if args.duration else None
    bus: list[Bus] = []
    reached: list[str] = []

    def done() -> bool:
        if bus:
            reached[:] = links(bus[0].session)  # (for the hint, should nothing come)
        return bool(recorder.paused) or (deadline is not None and time.monotonic() >= deadline)

    _run(recorder, args, env, lambda: "recording " + describe(recorder.status()), done, args.status_every,
         on_bus=bus.append)
    status = recorder.status()
    if recorder.paused:  # the disk: the file is finished (or only closed) as far as it got
        env.say("recorded " + describe({**status, "paused": ""}))
        print(f"sonibus: error: node 'record': {recorder.paused}", file=env.stderr, flush=True)
        return Exit.ERROR
    if status["messages"] == 0:  # a recording that heard nothing is no recording: said, and not left behind
        for path in recorder.files:
            with contextlib.suppress(OSError):
                os.unlink(path)
        print(f"sonibus: error: recorded nothing in {status['duration_s']:.1f} s: no message on "
              f"{' '.join(config.subscribe)}; {recorder.path} removed", file=env.stderr, flush=True)
        env.hint(reach_hint(bus_config(args), reached, "nothing came") if not reached else
                 f"this command reached {len(reached)} peer(s)/router(s): is a robot's node running there (sonibus "
                 "nodes)? A robot that is not connected sends nothing; or name what it publishes (KEYEXPR)")
        return Exit.NOT_FOUND
    env.say("recorded " + describe(status))
    return Exit.OK


RECORD = Command("record", "record the bus into an MCAP file", _record_arguments, _record, bus=True)


# -- replay -------------------------------------------------------------------------


def _replay_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.mcap")
    p.add_argument("--speed", type=float, default=1.0, help="playback speed (default: 1)")
    p.add_argument("--loop", action="store_true", help="start again at the end, until stopped")
    p.add_argument("--start", type=float, default=0.0, metavar="S", help="begin S seconds into the recording")
    p.add_argument("--end", type=float, metavar="S", help="end S seconds into the recording")
    p.add_argument("--as", dest="rename", action="append", default=[], metavar="NAME|ROBOT=NAME",
                   help="replay the robot under another name (ROBOT=NAME when it holds several)")
    p.add_argument("--keys", nargs="+", default=(), metavar="KEYEXPR", help="replay only these keys")
    p.add_argument("--max-gap", type=float, default=ReplayConfig.max_gap_s, metavar="S",
                   help="never wait longer than S seconds of the recording between two messages: a longer gap "
                        "is shortened, with a warning (default: %(default)g)")
    p.add_argument("--status-every", type=float, default=5.0, metavar="S",
                   help="seconds between progress lines when not on a terminal (default: 5)")


def _renames(words: list[str], path: str) -> dict[str, str]:
    renames = {}
    for word in words:
        old, sep, new = word.rpartition("=")
        if not sep:
            with Recording(path) as recording:
                robots = recording.robots
            if len(robots) != 1:
                raise ConfigError(f"--as {word}: {path} holds {', '.join(robots)}; say which, e.g. "
                                  f"--as {robots[0]}={word}")
            old = robots[0]
        renames[old] = new
    return renames


FLAGS = {"speed": "--speed", "start": "--start", "end": "--end", "max_gap_s": "--max-gap", "keys": "--keys",
         "rename": "--as"}  # ReplayConfig's keys as the command line names them


def _replay(args: argparse.Namespace, env: Environment) -> Exit:
    try:
        cfg = ReplayConfig(path=args.file, speed=args.speed, loop=args.loop, start=args.start, end=args.end,
                           rename=_renames(args.rename, args.file), keys=tuple(args.keys), max_gap_s=args.max_gap)
    except ConfigError as exc:  # "key 'speed': 0 must be ..." → "--speed 0 must be ..."
        key, _, problem = str(exc).removeprefix("key '").partition("': ")
        raise ConfigError(f"{FLAGS[key]} {problem}" if key in FLAGS else str(exc)) from None
    replay = Replay(cfg, name="replay")

    def progress() -> str:  # position_s counts from the window's start (--start)
        done = replay.position_s / replay.window_s if replay.window_s > 0 else 1.0
        bar = "#" * int(30 * min(done, 1.0))
        loop = f"  loop {replay.loops + 1}" if cfg.loop else ""
        return f"replay [{bar:<30}] {replay.position_s:6.1f}/{replay.window_s:.1f} s  x{cfg.speed:g}{loop}"

    _run(replay, args, env, progress, replay.finished.is_set, args.status_every)
    gaps = f", {replay.stats['gaps']} gaps shortened" if replay.stats["gaps"] else ""
    why = " (this machine was too busy to send them on time: its CPU)" if replay.stats["late"] else ""
    env.say(f"replayed {os.path.basename(args.file)}: {replay.stats['sent']} messages, "
            f"{replay.stats['late']} skipped as late{why}{gaps}"  # (what it could not read: warned, replay.py)
            + ("" if replay.listened.is_set() else "; heard by nobody: no node on the bus subscribed to them"))
    return Exit.OK


REPLAY = Command("replay", "play a recording back onto the bus", _replay_arguments, _replay, bus=True)


# -- info, recover ------------------------------------------------------------------


def _info_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.mcap|ROBOT", help="a recording, or the name of a robot on the bus")
    p.add_argument("--json", action="store_true", help="print it as JSON")
    p.add_argument("--timeout", type=float, default=2.0, help="ROBOT: seconds to wait for its answer")


def _info(args: argparse.Namespace, env: Environment) -> Exit:
    if _robot_name(args.file):
        return live_robot.show(args.file, args, env, args.json, args.timeout)
    try:
        recording = Recording(args.file)
    except StillRecording as live:
        return _info_live(live, args, env)
    with recording:
        infos = recording.infos()
        facts = {
            "file": args.file, "bytes": os.path.getsize(args.file),
            "start": recording.start_ns / 1e9, "duration_s": recording.duration_s,
            "messages": recording.message_count, "recorder": recording.metadata.get("sonibus.recording", {}),
            "stats": {k: _number(v) for k, v in recording.metadata.get("sonibus.stats", {}).items()},
            "robots": {r: {"model": infos.get(r, {}).get("model"), "rate_hz": infos.get(r, {}).get("rate_hz"),
                           "joints": sum(1 for k in recording.keys if k.startswith(f"{r}/joints/"))}
                       for r in recording.robots},
            "keys": {k: {"messages": recording.counts[k], "rate_hz": recording.rate_hz(k)} for k in recording.keys},
            "skipped": dict(recording.skipped),
        }
        _said(recording.problems())
    if args.json:
        env.say(json.dumps(facts, indent=2))
        return Exit.OK
    started = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(facts["start"]))
    env.say(f"{args.file}: {facts['bytes'] / 1e6:.2f} MB, {facts['messages']} messages, "
            f"{facts['duration_s']:.2f} s from {started}")
    if facts["recorder"]:
        about = facts["recorder"]
        part = f", file {about['part']} (after {about['previous']})" if about.get("previous") else ""
        env.say(f"  recorded by {about.get('node', '?')} on {about.get('host', '?')}{part}, "
                f"dropped {facts['stats'].get('dropped', '?')}")
    for robot, about in facts["robots"].items():
        rate = f"{about['rate_hz']:g} frames/s" if about["rate_hz"] else "no info"  # (checked: a number)
        env.say(f"  robot {robot}: {about['model'] or '?'}, {about['joints']} joints, {rate}")
    width = max((len(k) for k in facts["keys"]), default=0)  # (a file may hold no key a reader takes)
    for key, about in facts["keys"].items():
        env.say(f"    {key:<{width}}  {about['messages']:>8}  {about['rate_hz']:8.1f}/s")
    return Exit.OK


def _info_live(live: StillRecording, args: argparse.Namespace, env: Environment) -> Exit:
    """``info`` on a file a recorder is writing: who writes it, since when; no summary yet."""
    about = head(live.path)
    if args.json:
        env.say(json.dumps({"file": live.path, "bytes": live.size, "being_written": True, "recorder": about},
                           indent=2))
        return Exit.OK
    by = f", by {about.get('node', '?')} on {about.get('host', '?')} since {about['started']}" \
        if "started" in about else ""
    env.say(f"{live.path}: being written{by}, {live.size / 1e6:.2f} MB so far (a recorder that is running holds "
            "it); its summary comes when the recorder closes it, at its next file or when it stops")
    return Exit.OK


def _number(text: str) -> int | float | str:
    """An MCAP metadata value (always a string) as the number it holds, if it holds one."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _robot_name(word: str) -> bool:
    """A robot's name rather than a file: no such file, no path or extension, a valid key chunk."""
    if os.path.exists(word) or "." in word or "/" in word or os.sep in word:
        return False
    try:
        keys.check_name("robot", word)
    except ValueError:
        return False
    return True


INFO = Command("info", "what a recording holds, or a live robot's joints, behaviors and postures",
               _info_arguments, _info, bus=True)


def _recover_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.mcap")
    p.add_argument("-o", "--output", metavar="OUT.mcap", help="default: FILE.recovered.mcap")


def _recover(args: argparse.Namespace, env: Environment) -> Exit:
    out = args.output or os.path.splitext(args.file)[0] + ".recovered.mcap"
    if os.path.exists(out):
        raise RecordingError(f"{out} exists — choose another with -o")
    kept, skipped = recover(args.file, out)
    env.say(f"recovered {kept} messages from {args.file} into {out}")
    _said(skipped)
    return Exit.OK


RECOVER = Command("recover", "save what a damaged recording holds into a new file", _recover_arguments, _recover)


# -- export, plot -------------------------------------------------------------------


def _export_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.mcap")
    p.add_argument("--csv", metavar="DIR", help="folder for <robot>.csv and events.csv")
    p.add_argument("--wav", metavar="DIR", help="folder for <robot>-mic.wav and <robot>-speaker.wav (its audio)")


def _export(args: argparse.Namespace, env: Environment) -> Exit:
    if not args.csv and not args.wav:
        raise ConfigError("export needs --csv DIR (joints, derived values, events), --wav DIR (audio), or both")
    with Recording(args.file) as recording:
        for path in export_csv(recording, args.csv) if args.csv else ():
            env.say(path)
        if args.wav and not audio_keys(recording):
            env.say(f"no audio in {args.file}: no WAV written")
        for path in export_wav(recording, args.wav, env.say) if args.wav else ():
            env.say(path)
        _said(recording.problems())
    return Exit.OK


EXPORT = Command("export", "a recording as CSV files (one per robot, one of events) and WAV files (its audio)",
                 _export_arguments, _export)


def _plot_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.mcap")
    p.add_argument("-o", "--output", metavar="OUT.png", help="default: FILE.png (.svg and .pdf work too)")
    p.add_argument("--keys", nargs="+", metavar="KEYEXPR", help="plot only these keys")
    p.add_argument("--title", help="default: the file, its length and robots")


def _plot(args: argparse.Namespace, env: Environment) -> Exit:
    out = args.output or os.path.splitext(args.file)[0] + ".png"
    with Recording(args.file) as recording:
        env.say(plot(recording, out, args.keys, args.title))
        _said(recording.problems())
    return Exit.OK


PLOT = Command("plot", "joint trajectories per chain with behaviors and speech marked", _plot_arguments, _plot)
