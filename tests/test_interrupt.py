"""A Ctrl-C that lands in a finalizer (where Python prints "Exception ignored" and carries on) is not lost: the next
progress step raises it again, an atomic write publishes nothing, and the command exits 130."""
import gc
import os
import signal
import subprocess
import sys
import weakref

import pytest

from dcslam import interrupt
from dcslam.io.atomic import atomic_output
from dcslam.progress import track

pytestmark = pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")  # the swallowed one


@pytest.fixture
def handler():
    previous, hook = {s: signal.getsignal(s) for s in interrupt.SIGNALS}, sys.unraisablehook
    interrupt.install()
    yield
    for signum, action in previous.items():
        signal.signal(signum, action)
    sys.unraisablehook = hook
    interrupt._received = interrupt._told = False
    interrupt._signal = None


class _Resource:
    pass


def _swallowed_sigint():
    """SIGINT delivered while a weak-reference callback runs: Python reports it as 'Exception ignored'."""
    resource = _Resource()
    weakref.finalize(resource, lambda: os.kill(os.getpid(), signal.SIGINT) or [0 for _ in range(10_000)])
    del resource
    gc.collect()


def test_a_swallowed_interrupt_stops_the_next_progress_step(handler, capsys):
    steps = []
    with pytest.raises(KeyboardInterrupt):
        for i in track(range(5), "demo"):
            steps.append(i)
            if i == 1:
                _swallowed_sigint()
    assert steps == [0, 1] and interrupt.received()


def test_a_swallowed_interrupt_publishes_no_atomic_file(handler, tmp_path):
    target = tmp_path / "out.txt"
    with pytest.raises(KeyboardInterrupt):
        with atomic_output(target) as tmp:
            tmp.write_text("complete")
            _swallowed_sigint()
    assert list(tmp_path.iterdir()) == []


def test_command_line_exits_130_when_an_interrupt_was_swallowed(tmp_path):
    script = ("import dcslam.cli as c\n"
              "from tests.test_interrupt import _swallowed_sigint\n"
              "@c.app.command('swallow')\n"
              "def swallow():\n"
              "    _swallowed_sigint()\n"
              "c.main()\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([os.getcwd(), *sys.path])}
    done = subprocess.run([sys.executable, "-c", script, "swallow"], capture_output=True, text=True, env=env,
                          timeout=60)
    assert done.returncode == 130, done.stderr
    assert done.stderr.strip().splitlines()[-1] == \
        "interrupted: no partial output was kept; rerun the command to finish"
    # the swallowed one is recorded, not printed as a traceback (it failed test_faults when a Ctrl-C landed in a
    # WeakValueDictionary callback)
    assert "Exception ignored" not in done.stderr and "Traceback" not in done.stderr, done.stderr


def test_other_unraisable_exceptions_still_reach_pythons_hook(handler):
    seen = []
    sys.unraisablehook = lambda u: seen.append(type(u.exc_value))
    interrupt.install()                                    # wraps the hook in place now

    class Broken:
        def __del__(self):
            raise ValueError("in a finalizer")

    Broken()
    gc.collect()
    assert seen == [ValueError] and not interrupt.received()


def test_sigterm_is_an_interrupt_whose_exit_code_is_143(handler):
    with pytest.raises(KeyboardInterrupt):
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):  # the handler runs between bytecodes
            pass
    assert interrupt.received() and interrupt.exit_code() == 143
    with pytest.raises(KeyboardInterrupt):
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(1000):
            pass
    assert interrupt.exit_code() == 143  # the first signal decides


def test_an_interrupt_without_a_signal_exits_130(handler):
    assert interrupt.exit_code() == 130


def test_an_interrupt_a_c_extension_wrapped_is_still_one():
    def wrapped(cause):
        error = SystemError("<cyfunction FastRLock.__exit__> returned a result with an exception set")
        error.__cause__ = cause
        return error

    assert interrupt.is_interrupt(KeyboardInterrupt()) and interrupt.is_interrupt(wrapped(KeyboardInterrupt()))
    assert not interrupt.is_interrupt(SystemError("a bug")) and not interrupt.is_interrupt(wrapped(ValueError()))
    assert not interrupt.is_interrupt(ValueError())
    # a pybind11 module interrupted while it initialises (SciPy's HiGHS under a lazy `import scipy.stats`)
    failed = ImportError("initialization failed")
    failed.__cause__ = KeyboardInterrupt()
    assert interrupt.is_interrupt(failed) and not interrupt.is_interrupt(ImportError("No module named 'x'"))
