"""Recordings from strangers (issue 33): a crafted file never takes a command that
reads it (``info``, ``export``, ``plot``, ``replay``, ``recover``) past ``RSS_MB``
of memory, nor ends it with an internal error; it is refused in one line, or read
with what cannot be read skipped and counted."""

from __future__ import annotations

import io
import json
import subprocess
import sys
import time

import pytest

from sonibus.adapters.recorder.bounded import MAX_CHANNELS, MAX_TOPIC
from sonibus.adapters.recorder.reading import Message, Recording
from sonibus.adapters.recorder.replay import _moments
from sonibus.bus.cli import Environment, main
from sonibus.bus.messages import MAX_JOINTS

from .crafted import MAGIC, Part, Recipe, Topic, compress, craft, jsons, lz4_zeros, message, samples, zstd_zeros
from .fuzz_files import COMMANDS as FUZZED
from .fuzz_files import INTERNAL, info, judge, mutants

RSS_MB = 200
COMMANDS = ("info", "export", "plot", "replay", "recover")


def argv(command, path, tmp):
    extra = {"export": ["--csv", str(tmp / "csv")], "plot": ["-o", str(tmp / "out.png")],
             "replay": ["--no-multicast"], "recover": ["-o", str(tmp / "recovered.mcap")]}
    return [command, str(path), *extra.get(command, [])]


def cli(*args):
    env = Environment(stdout=io.StringIO(), stderr=io.StringIO())
    return main(list(args), env), env.stdout.getvalue(), env.stderr.getvalue()


def clean(status, err, command):
    """A success (warnings allowed) or one line of a refusal that is not an internal error."""
    assert status in (0, 1), (command, status, err)
    lines = err.splitlines()
    assert "Traceback" not in err, (command, err)
    if status == 1:
        assert len(lines) == 1 and lines[0].startswith("sonibus: error: ") and not INTERNAL.match(lines[0]), \
            (command, err)
    else:
        assert all(line.startswith(("sonibus: WARNING: ", "replay [")) for line in lines), (command, err)


# -- the files ----------------------------------------------------------------------------------

HEAD_YAW = [Topic(1, "pepper/joints/HeadYaw", count=20)]


def zstd_bomb(path):  # the 98 KB file of the issue: one chunk that expands to 3 GiB, as it says
    craft(path, Recipe(parts=[Part(data=zstd_zeros(3 << 30), declared=3 << 30)]))


def zstd_liar(path):  # the same chunk saying it expands to 1,000 bytes
    craft(path, Recipe(parts=[Part(data=zstd_zeros(3 << 30), declared=1000)]))


def lz4_bomb(path):  # 4.2 MB of lz4 that expands to 1 GiB
    craft(path, Recipe(parts=[Part(compression="lz4", data=lz4_zeros(1 << 30), declared=1 << 30)]))


def lz4_liar(path):
    craft(path, Recipe(parts=[Part(compression="lz4", data=lz4_zeros(1 << 30), declared=1000)]))


def tiny_messages(path):  # 256 MiB of 33-byte messages in 16 honest chunks, 27 KB on disk
    tiny = message(1, 0, b"{}") * ((16 << 20) // 33)
    craft(path, Recipe(topics=[Topic(1, "pepper/info", count=16 * ((16 << 20) // 33))],
                       parts=[Part(tiny) for _ in range(16)]))


def index_liar(path):  # the chunk says 1 MiB, the file's index 1 KiB
    craft(path, Recipe(parts=[Part(samples(1, 10), indexed=1024)]))


BOMBS = {"zstd bomb": zstd_bomb, "zstd liar": zstd_liar, "lz4 bomb": lz4_bomb, "lz4 liar": lz4_liar,
         "tiny messages": tiny_messages}

DRIVER = """
import io, json, sys
from sonibus.bus.cli import Environment, main
found = []
for args in json.loads(sys.argv[1]):
    env = Environment(stdout=io.StringIO(), stderr=io.StringIO())
    found.append((args[0], main(args, env), env.stderr.getvalue()))
with open("/proc/self/status") as f:
    peak = next(int(line.split()[1]) for line in f if line.startswith("VmHWM:"))
print(json.dumps({"peak_mb": peak / 1024, "found": found}))
"""


def rss_mb(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:")) / 1024
    except (OSError, StopIteration):
        return 0.0


def measured(runs):
    """``runs`` (argument lists) in turn in one child process: its peak RSS (VmHWM) and what each said.
    A watchdog ends it past twice ``RSS_MB`` or after 60 s (before the fix the bombs went past 2 GB)."""
    child = subprocess.Popen([sys.executable, "-c", DRIVER, json.dumps(runs)], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    deadline, peak = time.monotonic() + 60, 0.0
    try:
        while child.poll() is None:
            peak = max(peak, rss_mb(child.pid))
            assert peak < 2 * RSS_MB, f"past {peak:.0f} MB"
            assert time.monotonic() < deadline, "still running after 60 s"
            time.sleep(0.005)
        out, err = child.communicate()
    finally:
        child.kill()
        child.wait()
    assert child.returncode == 0, err
    return json.loads(out)


@pytest.mark.parametrize("make", list(BOMBS.values()), ids=list(BOMBS))
def test_a_bomb_takes_no_command_past_the_memory_bound(tmp_path, make, figure):
    """Every reading command, one after the other in one process: its peak stays under RSS_MB."""
    path = tmp_path / "bomb.mcap"
    make(path)
    report = measured([argv(command, path, tmp_path) for command in COMMANDS])
    figure("peak RSS", report["peak_mb"], "MB")
    assert report["peak_mb"] < RSS_MB, report
    for command, status, said in report["found"]:
        clean(status, said, command)
        assert status == 1, (command, said)  # nothing in it can be read


def test_a_plot_of_twenty_thousand_events_marks_the_first_and_says_so(tmp_path, figure):
    """matplotlib took minutes and GBs over 20,000 behavior spans before."""
    path = tmp_path / "events.mcap"
    events = [json.dumps({"t": 1.7e9 + i / 100, "kind": "behavior", "name": f"b{i % 50}",
                          "state": ("started", "stopped")[i % 2]}).encode() for i in range(20_000)]
    craft(path, Recipe(topics=[Topic(1, "pepper/joints/HeadYaw", count=10),
                               Topic(2, "pepper/events/behavior", count=len(events))],
                       parts=[Part(samples(1, 10) + jsons(2, events, 10), channels=(1, 2))]))
    report = measured([argv("plot", path, tmp_path)])
    figure("peak RSS", report["peak_mb"], "MB")
    [(_, status, said)] = report["found"]
    assert status == 0 and report["peak_mb"] < RSS_MB, report
    assert said == f"sonibus: WARNING: {path}: 19500 events not marked: a picture marks at most the first 500 of " \
                   "a robot\n", said


@pytest.mark.parametrize("make, why", [
    (zstd_bomb, "the chunk at byte 82 expands to 3072.0 MiB, more than a chunk may (32.0 MiB"),
    (zstd_liar, "the chunk at byte 82 expands to more than the 1000 bytes it says"),
    (lz4_bomb, "the chunk at byte 82 expands to 1024.0 MiB, more than a chunk may"),
    (lz4_liar, "the chunk at byte 82 expands to more than the 1000 bytes it says"),
    (tiny_messages, "its chunks expand to 256.0 MiB, 9822 times its size (at most 200 times"),
], ids=["zstd bomb", "zstd liar", "lz4 bomb", "lz4 liar", "tiny messages"])
def test_a_file_that_lies_about_its_sizes_is_refused_in_one_line_without_the_recover_hint(tmp_path, make, why):
    path = tmp_path / "liar.mcap"
    make(path)
    for command in ("info", "export"):
        status, _, err = cli(*argv(command, path, tmp_path))
        clean(status, err, command)
        assert status == 1 and why in err and "recover" not in err, err
    status, _, err = cli(*argv("recover", path, tmp_path))
    assert status == 1 and "nothing to recover" in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "recovered.mcap").exists()


def test_a_chunk_its_index_lies_about_is_refused_with_the_recover_hint_and_recovered(tmp_path):
    path = tmp_path / "liar.mcap"
    index_liar(path)
    status, _, err = cli("info", str(path))
    clean(status, err, "info")
    assert status == 1 and "the chunk at byte 82 says it holds 206 bytes of zstd data expanding to 719 bytes; the " \
        f"file's index says 206 bytes of zstd to 1024 bytes; 'sonibus recover {path}' reads its chunks" in err, err
    status, out, err = cli(*argv("recover", path, tmp_path))
    assert status == 0 and err == "" and "recovered 10 messages" in out, err
    assert cli("export", str(tmp_path / "recovered.mcap"), "--csv", str(tmp_path / "csv"))[0] == 0


BAD_JSON = [b"[" * 100_000 + b"]" * 100_000, b"{" * 50_000, b'{"t":' * 3000 + b"1" + b"}" * 3000, b"1", b"[1, 2]",
            b'"x"', b"null", b"\xff\xfe", b'{"t": "soon", "seq": 0, "v": 1}', b'{"t": 1.7e9, "seq": 0, "v": [1]}',
            b'{"t": 1.7e9, "kind": "behavior", "args": [[[]]], "state": "started", "name": {"a": 1}}']


def bad_json(path):
    """Joint samples and events, with ``BAD_JSON`` on both keys among them."""
    craft(path, Recipe(topics=[Topic(1, "pepper/joints/HeadYaw", count=20 + len(BAD_JSON)),
                               Topic(2, "pepper/events/behavior", count=len(BAD_JSON))],
                       parts=[Part(samples(1, 10) + jsons(2, BAD_JSON, 10) + jsons(1, BAD_JSON, 30) +
                                   samples(1, 10, 60), channels=(1, 2))]))


def test_deep_or_non_object_json_is_skipped_and_counted(tmp_path):
    """RecursionError and TypeError ended every command before."""
    path = tmp_path / "json.mcap"
    bad_json(path)
    skipped = f"{path}: skipped {2 * len(BAD_JSON)} messages (the first: "
    for command in ("export", "plot", "recover"):
        status, out, err = cli(*argv(command, path, tmp_path))
        clean(status, err, command)
        assert status == 0 and err.startswith(f"sonibus: WARNING: {skipped}"), (command, err)
    assert "recovered 20 messages" in out
    with open(tmp_path / "csv" / "pepper.csv") as f:
        assert len(f.read().splitlines()) == 1 + 20
    status, out, err = cli("info", str(tmp_path / "recovered.mcap"))
    assert status == 0 and "pepper/joints/HeadYaw" in out and err == "", err


def corrupt(path, compression, how):
    """Two chunks of ten samples; the first one's compressed data corrupt (``how``: its bytes after the
    compression's magic replaced, or one flipped so only its CRC tells)."""
    good = samples(1, 10)
    data = bytearray(compress(good, compression))
    if how == "garbage":
        data[4:] = bytes((i * 37 + 11) % 256 for i in range(len(data) - 4))
    else:
        data[len(data) // 2] ^= 0xFF
    craft(path, Recipe(topics=HEAD_YAW, parts=[Part(good, compression=compression, data=bytes(data)),
                                               Part(samples(1, 10, 10))]))


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
@pytest.mark.parametrize("how", ["garbage", "a flipped byte"])
def test_a_corrupt_chunk_is_skipped_and_counted(tmp_path, compression, how):
    """A ZstdError (or lz4's RuntimeError) ended every command before; recover gave up at it."""
    path = tmp_path / "corrupt.mcap"
    corrupt(path, compression, how)
    for command in ("export", "plot", "recover"):
        status, out, err = cli(*argv(command, path, tmp_path))
        clean(status, err, command)
        assert status == 0 and f"{path}: skipped 1 chunk (the first: the chunk at byte 82 " in err, (command, err)
    status, out, _ = cli("info", str(tmp_path / "recovered.mcap"))
    assert status == 0 and "10 messages" in out, out
    with open(tmp_path / "csv" / "pepper.csv") as f:
        assert [row.split(",")[2] for row in f.read().splitlines()[1:]] == [str(seq) for seq in range(10, 20)]


def test_replay_skips_a_corrupt_chunk_and_counts_it(tmp_path):
    """Replay's worker failed on a ZstdError before: the node ended with it."""
    path = tmp_path / "corrupt.mcap"
    corrupt(path, "zstd", "garbage")
    status, out, err = cli(*argv("replay", path, tmp_path))
    clean(status, err, "replay")
    assert status == 0 and "replayed corrupt.mcap: 10 messages" in out, (out, err)
    assert "skipped 1 chunk (the first: the chunk at byte 82 is corrupt (zstd:" in err, err


def test_a_megabyte_topic_name_is_refused_at_once(tmp_path):
    """plot hung on it before."""
    path = tmp_path / "long.mcap"
    craft(path, Recipe(topics=[Topic(1, "pepper/joints/" + "J" * (1 << 20), count=10)], parts=[Part(samples(1, 10))]))
    for command in ("info", "plot", "replay"):
        status, _, err = cli(*argv(command, path, tmp_path))
        clean(status, err, command)
        assert status == 1 and f"holds a channel named by {(1 << 20) + 14} characters" in err, err
        assert f"more than a key may ({MAX_TOPIC})" in err


def many_channels(path, count, robots):
    topics = [Topic(i, f"r{i}/joints/J" if robots else f"pepper/joints/J{i}", count=1) for i in range(1, count + 1)]
    content = b"".join(message(i, 0, b'{"t":1.7e9,"seq":0,"v":0.1}') for i in range(1, count + 1))
    craft(path, Recipe(topics=topics, parts=[Part(content)]))


def test_65535_channels_are_refused_and_a_picture_or_replay_of_thousands_of_robots_too(tmp_path):
    """plot and replay hung on 65,535 channels before (and took minutes and GBs on 4,096)."""
    path = tmp_path / "many.mcap"
    many_channels(path, 65535, robots=True)
    for command in ("info", "plot", "replay"):
        status, _, err = cli(*argv(command, path, tmp_path))
        clean(status, err, command)
        assert status == 1 and f"holds 65535 channels, more than sonibus reads ({MAX_CHANNELS}" in err, err
    many_channels(path, MAX_CHANNELS, robots=True)
    status, _, err = cli(*argv("replay", path, tmp_path))
    assert status == 1 and "holds 4096 robots (r1, r10, r100, ...); a replay takes at most 64" in err, err
    status, _, err = cli(*argv("plot", path, tmp_path))
    assert status == 1 and "too much for one picture (4096 joints in 4096 panels" in err, err
    assert "--keys 'r1/joints/*'" in err


def test_a_fuzz_of_crafted_recordings(tmp_path):
    """A small, deterministic slice (bench/recording_fuzz.py runs thousands): payloads of every kind,
    lying sizes, garbage chunks, flipped bytes, cut files; ``info``, ``export`` and ``recover`` on each,
    ``plot`` on some (it found the OSError of an offset outside the file)."""
    wrong = []
    for n, (_, path) in enumerate(mutants(seed=33, count=60, folder=tmp_path)):
        wrong += judge(path, (*FUZZED, "plot") if n % 12 == 0 else FUZZED)
    assert not wrong, "\n".join(wrong)


def test_a_frame_of_thousands_of_joints_is_replayed_in_moments_of_a_frame_each():
    """Replay reads 512 moments ahead: a file's frame of 4,096 joints made each moment 4,096 messages."""
    samples_ = [Message(f"pepper/joints/J{n}", 10**18, 10**18, {"t": 1.7e9, "seq": 0, "v": 0.1}) for n in range(300)]
    assert [len(moment) for framed, moment in _moments(samples_)] == [MAX_JOINTS, MAX_JOINTS, 300 - 2 * MAX_JOINTS]


def test_info_reads_the_last_info_from_the_last_chunk_that_holds_one(tmp_path):
    """``info`` read every recorded info to keep the last (50 s for a file of a million): now it reads
    backwards from the last chunk, so the corrupt chunks before it are never even opened."""
    path = tmp_path / "infos.mcap"
    good = jsons(1, [info()], 0)
    craft(path, Recipe(topics=[Topic(1, "pepper/info", count=5)],
                       parts=[*(Part(good, data=b"\x28\xb5\x2f\xfd" + bytes(40)) for _ in range(4)), Part(good)]))
    with Recording(str(path)) as recording:
        assert recording.infos()["pepper"]["model"] == "pepper"
        assert recording.skipped == {"messages": 0, "chunks": 0}


def test_a_channel_zenoh_takes_for_no_key_is_left_out(tmp_path):
    """``--keys`` and replay took every topic apart with Zenoh: "pepper/joints/a*b" ended them with ZError."""
    path = tmp_path / "keys.mcap"
    craft(path, Recipe(topics=[Topic(1, "pepper/joints/HeadYaw", count=10), Topic(2, "pepper/joints/a*b", count=10)],
                       parts=[Part(samples(1, 10) + samples(2, 10), channels=(1, 2))]))
    for args in ([*argv("plot", path, tmp_path), "--keys", "pepper/**"], argv("replay", path, tmp_path),
                 argv("info", path, tmp_path)):
        status, out, err = cli(*args)
        clean(status, err, args[0])
        assert status == 0 and "a*b" not in out, (args, out, err)
    craft(path, Recipe(topics=[Topic(2, "pepper/joints/a*b", count=10)], parts=[Part(samples(2, 10), channels=(2,))]))
    for command in ("info", "export", "plot", "replay"):  # (info ended with "max() arg is an empty sequence")
        status, out, err = cli(*argv(command, path, tmp_path))
        clean(status, err, command)
        assert "a*b" not in out, (command, out)


def test_a_file_shorter_than_a_footer_between_its_magics_is_refused_in_one_line(tmp_path):
    """The fuzz campaign's find: a cut that kept the magic at its end; info ended with OSError (a seek before 0)."""
    path = tmp_path / "short.mcap"
    path.write_bytes(MAGIC + b"\x01\x02\x03\x04\x05\x06\x07" + MAGIC)
    for command in ("info", "export", "plot", "replay"):
        status, _, err = cli(*argv(command, path, tmp_path))
        clean(status, err, command)
        assert status == 1 and "is damaged (McapError: an offset (-14) outside the file (23 bytes))" in err, err
