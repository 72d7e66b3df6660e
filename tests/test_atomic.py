"""Atomic output: the target appears complete or not at all, with the usual permissions."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from mountcal.core import atomic
from mountcal.core.atomic import atomic_output, atomic_path


class Boom(Exception):
    pass


@pytest.fixture(params=["o_tmpfile", "renamed temporary"])
def how(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    if request.param == "renamed temporary":  # a file system without O_TMPFILE
        monkeypatch.delattr(atomic.os, "O_TMPFILE")
    return str(request.param)


def test_output_appears_whole_and_replaces_an_old_file(tmp_path: Path, how: str) -> None:
    target = tmp_path / "out" / "data.bin"
    with atomic_output(target) as f:
        f.write(b"first")
        assert not target.exists()  # nothing under the name while writing
    with atomic_output(target) as f:
        f.write(b"second")
    assert target.read_bytes() == b"second"
    assert sorted(p.name for p in target.parent.iterdir()) == ["data.bin"]  # no temporary left
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~umask


def test_an_error_leaves_the_old_file_and_no_temporary(tmp_path: Path, how: str) -> None:
    target = tmp_path / "data.bin"
    target.write_bytes(b"old")
    with pytest.raises(Boom), atomic_output(target) as f:
        f.write(b"half")
        raise Boom
    assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["data.bin"]


@pytest.mark.parametrize("durable", [True, False])
def test_atomic_path_renames_on_success_and_cleans_up_on_error(tmp_path: Path, durable: bool) -> None:
    target = tmp_path / "table.csv"
    with atomic_path(target, durable=durable) as tmp:
        tmp.write_text("a,b\n1,2\n")
        assert tmp.parent == tmp_path and tmp.name.startswith(".table.csv.") and not target.exists()
    assert target.read_text() == "a,b\n1,2\n"
    with pytest.raises(Boom), atomic_path(target, durable=durable) as tmp:
        tmp.write_text("broken")
        raise Boom
    assert target.read_text() == "a,b\n1,2\n"
    assert [p.name for p in tmp_path.iterdir()] == ["table.csv"]


def test_atomic_path_can_keep_the_target_s_file_name(tmp_path: Path) -> None:
    target = tmp_path / "log.mf4"
    with atomic_path(target, keep_name=True) as tmp:
        assert tmp.name == "log.mf4" and tmp.parent.parent == tmp_path and tmp.parent.name.startswith(".log.mf4.")
        tmp.write_bytes(b"whole")
        (tmp.parent / "side.tmp").write_bytes(b"a writer's own temporary")
    assert target.read_bytes() == b"whole" and [p.name for p in tmp_path.iterdir()] == ["log.mf4"]
    with pytest.raises(Boom), atomic_path(target, keep_name=True) as tmp:
        tmp.write_bytes(b"half")
        raise Boom
    assert target.read_bytes() == b"whole" and [p.name for p in tmp_path.iterdir()] == ["log.mf4"]


def test_a_growing_file_is_cut_back_to_its_last_whole_record(tmp_path: Path) -> None:
    import subprocess
    import sys

    code = (
        "import resource, signal, sys\n"
        "from mountcal.core.atomic import GrowingFile\n"
        "from mountcal.core.paths import SystemFailure\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (10000, 10000))\n"
        "f = GrowingFile(sys.argv[1], 'the records', hidden=4)\n"
        "try:\n"
        "    for i in range(100):\n"
        "        f.write(b'HEAD' + bytes([i]) * 996)\n"
        "        f.commit()\n"
        "except SystemFailure as err:\n"
        "    print(err)\n"
        "f.close()\n"
    )
    path = tmp_path / "records.bin"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1] / "src")}
    done = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, env=env, check=True)
    assert "File too large" in done.stdout and "10000 bytes, whole records only" in done.stdout
    data = path.read_bytes()
    assert len(data) == 10000 and all(data[k * 1000 : k * 1000 + 4] == b"HEAD" for k in range(10))


def test_a_growing_file_replaces_a_link_instead_of_writing_through_it(tmp_path: Path) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    link = tmp_path / "rec.blf"
    link.symlink_to(victim)
    f = atomic.GrowingFile(link, "the recording")
    f.write(b"new")
    f.close()
    assert victim.read_text() == "keep me" and link.read_bytes() == b"new" and not link.is_symlink()


def _drop_a_ctrl_c_in_a_callback() -> None:
    """Raise KeyboardInterrupt in a weakref callback: where a Ctrl-C's handler raises when the signal
    lands in one, and Python only prints it ("Exception ignored") and goes on."""
    import gc
    import weakref

    class Thing:
        pass

    def callback(_: object) -> None:
        raise KeyboardInterrupt

    thing = Thing()
    ref = weakref.ref(thing, callback)
    del thing
    gc.collect()
    assert ref() is None


def test_a_ctrl_c_python_drops_in_a_callback_is_kept_not_printed(capsys: pytest.CaptureFixture[str]) -> None:
    """Within removed_on_signals a Ctrl-C dropped in a callback is kept for raise_if_interrupted, silently."""
    from mountcal.core.atomic import raise_if_interrupted, removed_on_signals

    with removed_on_signals():
        _drop_a_ctrl_c_in_a_callback()
        with pytest.raises(KeyboardInterrupt):
            raise_if_interrupted()
    assert "KeyboardInterrupt" not in capsys.readouterr().err
    raise_if_interrupted()  # outside its block a dropped Ctrl-C is not kept


def test_an_output_is_not_named_after_a_ctrl_c_python_dropped(tmp_path: Path) -> None:
    """The Ctrl-C kept by removed_on_signals stops an atomic write at its commit: nothing is named."""
    from mountcal.core.atomic import atomic_output, atomic_path, removed_on_signals

    with removed_on_signals():
        _drop_a_ctrl_c_in_a_callback()
        for write in (atomic_path, atomic_output):
            target = tmp_path / f"{write.__name__}.json"
            with pytest.raises(KeyboardInterrupt), write(target) as out:
                if isinstance(out, Path):
                    out.write_text("{}")
                else:
                    out.write(b"{}")
            assert not target.exists()
    assert list(tmp_path.iterdir()) == []


_BLOCKED_CLEAN_UP = """
import os, signal, sys, threading, time
import mountcal.core.atomic as atomic
atomic.GRACE_S = 1.0
held = threading.Lock()
held.acquire()
with atomic.removed_on_signals():
    try:
        os.kill(os.getpid(), signal.{sig})
        time.sleep(30)
    except KeyboardInterrupt:
        held.acquire()  # a clean-up that waits for good (a lock the interrupted code held)
print("unreachable")
"""


@pytest.mark.parametrize(("sig", "code"), [("SIGINT", 130), ("SIGTERM", 143)])
def test_an_interrupted_command_whose_clean_up_blocks_ends_within_the_grace(sig: str, code: int) -> None:
    import subprocess
    import sys
    import time

    started = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-c", _BLOCKED_CLEAN_UP.format(sig=sig)],
        capture_output=True,
        text=True,
        timeout=30,
        preexec_fn=_sigint_default,
    )
    assert done.returncode == code and time.monotonic() - started < 10
    assert "clean-up has not ended" in done.stderr and "Run the same command again" in done.stderr
    assert "unreachable" not in done.stdout and "Traceback" not in done.stderr


def test_an_interrupted_command_s_exit_ends_within_the_grace_and_a_finished_block_is_disarmed() -> None:
    """The command line arms a deadline for its own exit (a thread that Python would join for good);
    a removed_on_signals block that ended, interrupted or not, ends nothing later."""
    import subprocess
    import sys

    script = (
        "import os, signal, threading, time, mountcal.core.atomic as atomic\n"
        "atomic.GRACE_S = 1.0\n"
        "with atomic.removed_on_signals():\n"
        "    pass\n"
        "try:\n"
        "    with atomic.removed_on_signals():\n"
        "        os.kill(os.getpid(), signal.SIGINT)\n"
        "        time.sleep(30)\n"
        "except KeyboardInterrupt:\n"
        "    pass\n"
        "time.sleep(2.5)\n"  # the two blocks' deadlines are disarmed: nothing ends the process here
        "print('alive', flush=True)\n"
        "threading.Thread(target=time.sleep, args=(60,)).start()  # joined at exit, for a minute\n"
        "atomic.Deadline().arm(130)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=30, preexec_fn=_sigint_default
    )
    assert done.stdout == "alive\n" and done.returncode == 130, (done.stdout, done.stderr)


def _sigint_default() -> None:
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)  # as in a foreground job (a background shell ignores it)
