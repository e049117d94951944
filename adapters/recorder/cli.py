"""The recording subcommands: ``sonibus record``, ``replay``, ``info``, ``recover``,
``export`` and ``plot`` (registered in the ``sonibus.commands`` entry-point group)."""

from __future__ import annotations

import argparse
import json
import os
import threading
import time
from collections.abc import Callable

from sonibus.bus import keys, runner
from sonibus.bus.cli import robot as live_robot
from sonibus.bus.cli.api import Command, Environment, Exit, bus_config
from sonibus.bus.errors import ConfigError

from .export import export_csv
from .plot import plot
from .reading import Recording, RecordingError, recover
from .recorder import Recorder, RecorderConfig, describe
from .replay import Replay, ReplayConfig
from .wav import audio_keys, export_wav


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
         line: Callable[[], str], done: Callable[[], bool] = lambda: False, every_s: float = 1.0) -> None:
    """Run ``adapter`` with a status line until it is ``done()`` or stopped; Ctrl-C
    and SIGTERM are the normal way to end it (the caller reports what was done)."""
    status: list[threading.Thread] = []
    try:
        runner.run([adapter], bus_config(args), env.stop,
                   on_started=lambda bus: status.append(_while_running(env, line, done, every_s)))
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
                   help="what to record (default: joints, derived values and events of every robot)")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument("--per-joint-keys", action="store_true",
                   help="record joint keys as published, not from frames (for publishers that put no frames)")
    p.add_argument("--no-foxglove", dest="foxglove", action="store_false",
                   help="leave out the channels Foxglove's panels read (frames whole, events as logs, arm transforms)")
    p.add_argument("--status-every", type=float, default=5.0, metavar="S",
                   help="seconds between status lines when not on a terminal (default: 5)")


def _record(args: argparse.Namespace, env: Environment) -> Exit:
    options = {"subscribe": tuple(args.keyexpr)} if args.keyexpr else {}
    try:
        config = RecorderConfig(path=args.file, overwrite=args.force, status_every_s=0,
                                per_joint_keys=args.per_joint_keys, foxglove=args.foxglove, **options)
    except ConfigError as exc:  # named as the node would be at start
        raise ConfigError(f"node 'record': {exc}") from None
    recorder = Recorder(config, name="record")
    deadline = time.monotonic() + args.duration if args.duration else None
    _run(recorder, args, env, lambda: "recording " + describe(recorder.status()),
         lambda: deadline is not None and time.monotonic() >= deadline, args.status_every)
    env.say("recorded " + describe(recorder.status()))
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
    env.say(f"replayed {os.path.basename(args.file)}: {replay.stats['sent']} messages, "
            f"{replay.stats['late']} skipped as late{gaps}")
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
    with Recording(args.file) as recording:
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
        }
    if args.json:
        env.say(json.dumps(facts, indent=2))
        return Exit.OK
    started = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(facts["start"]))
    env.say(f"{args.file}: {facts['bytes'] / 1e6:.2f} MB, {facts['messages']} messages, "
            f"{facts['duration_s']:.2f} s from {started}")
    if facts["recorder"]:
        env.say(f"  recorded by {facts['recorder'].get('node', '?')} on {facts['recorder'].get('host', '?')}, "
                f"dropped {facts['stats'].get('dropped', '?')}")
    for robot, about in facts["robots"].items():
        rate = f"{about['rate_hz']:g} frames/s" if about["rate_hz"] else "no info"
        env.say(f"  robot {robot}: {about['model'] or '?'}, {about['joints']} joints, {rate}")
    width = max(len(k) for k in facts["keys"])
    for key, about in facts["keys"].items():
        env.say(f"    {key:<{width}}  {about['messages']:>8}  {about['rate_hz']:8.1f}/s")
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
    kept = recover(args.file, out)
    env.say(f"recovered {kept} messages from {args.file} into {out}")
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
    return Exit.OK


PLOT = Command("plot", "joint trajectories per chain with behaviors and speech marked", _plot_arguments, _plot)
