"""Ctrl-C and SIGTERM, held one way (qpavoid.core.signals): deferred, noted, or ending the
command once, whatever the timing.

The cases that end a process run in a subprocess: once a command is stopped, the process
ignores both signals until it exits, which must not happen to the test run's own process.
"""

from __future__ import annotations

import os
import signal
import subprocess
import textwrap

import pytest
from conftest import PYTHON

from qpavoid.core.signals import Interruption, held, stops_raise


def python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*PYTHON, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=120,
    )


needs_python_ctrl_c = pytest.mark.skipif(
    signal.getsignal(signal.SIGINT) is not signal.default_int_handler,
    reason="Ctrl-C is not Python's KeyboardInterrupt here",
)


@needs_python_ctrl_c
def test_a_held_ctrl_c_comes_right_after_the_block():
    done = []
    with pytest.raises(KeyboardInterrupt), held():
        os.kill(os.getpid(), signal.SIGINT)
        done.append("the block ran to its end")
    assert done == ["the block ran to its end"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@needs_python_ctrl_c
def test_an_interruption_notes_ctrl_c_and_puts_the_handler_back():
    with Interruption(True) as stop:
        os.kill(os.getpid(), signal.SIGINT)
        assert stop.requested
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with Interruption(False) as idle:  # not active: nothing replaced
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    assert not idle.requested


def test_a_stopped_command_ignores_further_stops_until_it_exits():
    """The first Ctrl-C raises; the second, in the clean-up, changes nothing."""
    r = python(
        """
        import os, signal
        from qpavoid.core.signals import stops_raise
        try:
            with stops_raise() as received:
                os.kill(os.getpid(), signal.SIGINT)
                raise SystemExit("not interrupted")
        except KeyboardInterrupt:
            assert received == [signal.SIGINT]
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
            os.kill(os.getpid(), signal.SIGINT)  # a second Ctrl-C during the clean-up
            os.kill(os.getpid(), signal.SIGTERM)
            print("cleaned up")
        """
    )
    assert (r.returncode, r.stdout, r.stderr) == (0, "cleaned up\n", "")


def test_sigterm_raises_terminated_and_a_program_s_own_handler_is_left_alone():
    r = python(
        """
        import os, signal
        from qpavoid.core.errors import Terminated
        from qpavoid.core.signals import stops_raise
        mine = lambda signum, frame: print("the program's own")
        signal.signal(signal.SIGINT, mine)
        try:
            with stops_raise():
                os.kill(os.getpid(), signal.SIGINT)  # handled by the program
                os.kill(os.getpid(), signal.SIGTERM)
        except Terminated:
            print("terminated")
        """
    )
    assert (r.returncode, r.stdout, r.stderr) == (0, "the program's own\nterminated\n", "")


def test_a_second_ctrl_c_while_python_finalizes_leaves_the_status_as_it_was():
    """The cause of `ctrl-c twice` failing on a loaded machine (status -2, not 130): after
    its line, the process was still exiting (a tenth of a second tearing down numba and
    Pinocchio) when the test's second Ctrl-C came, and Python, finalizing, had put SIGINT
    back to the default: the signal killed it. Here the second Ctrl-C is sent from a
    finalizer that runs in that very moment, so no timing is involved."""
    r = python(
        """
        import os, signal, sys
        from qpavoid.cli.args import run_command

        class SecondCtrlC:
            def __del__(self, kill=os.kill, pid=os.getpid(), sigint=signal.SIGINT):
                kill(pid, sigint)  # while the interpreter tears its modules down

        late = SecondCtrlC()

        def command():
            os.kill(os.getpid(), signal.SIGINT)
            return "not interrupted"

        sys.exit(run_command(command))
        """
    )
    assert r.returncode == 130, r.stderr
    assert r.stderr == "qpavoid: interrupted; nothing written\n"


def test_stops_raise_in_another_thread_sets_nothing():
    import threading

    seen = []

    def worker():
        with stops_raise() as received:
            seen.append((received, signal.getsignal(signal.SIGTERM)))

    before = signal.getsignal(signal.SIGTERM)
    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert seen == [([], before)]
