"""Reliability, second pass: SIGTERM ends a sweep as Ctrl-C does, saying so (exit 143)."""

from __future__ import annotations

import signal
import time

from helpers import ENV, TIMEOUT, TINY_RUN, cli, finish


def test_sigterm_ends_the_sweep_with_a_message(tmp_path):
    proc = cli(*TINY_RUN, "anneal.steps=200000000", "anneal.trace_every=100000", f"output_dir={tmp_path}")

    def past_planning():
        deadline = time.monotonic() + TIMEOUT
        while not list(tmp_path.glob("runs/*.zarr/zarr.json")):  # the sweep is past planning
            assert time.monotonic() < deadline and proc.poll() is None, "no store was created"
            time.sleep(0.1)

    code, output = terminate_when(proc, past_planning)
    assert code == 143, output
    assert "vasc_pipeline: terminated (SIGTERM). Finished runs are stored" in output, output
    assert "Traceback" not in output, output


def terminate_when(proc, ready) -> tuple[int, str]:
    """SIGTERM ``proc`` once ``ready()`` returns; (exit status, output). Killed if a check fails."""
    try:
        ready()
        proc.send_signal(signal.SIGTERM)
        return finish(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_sigterm_while_the_kernels_compile_ends_the_sweep(tmp_path):
    """On a cold numba cache the sweep first compiles for minutes; SIGTERM then ends it at once
    (llvmlite's callbacks, in which numba compiles, swallowed the interrupt: the sweep ran on)."""
    env = {**ENV, "NUMBA_CACHE_DIR": str(tmp_path / "numba_cache")}
    proc = cli(*TINY_RUN, f"output_dir={tmp_path / 'out'}", env=env)

    def compiling():
        seen = []
        for line in proc.stderr:  # ends at EOF if the notice never comes
            seen.append(line)
            if "compiling the numba kernels" in line:
                break
        assert any("compiling the numba kernels" in line for line in seen), "".join(seen)

    code, output = terminate_when(proc, compiling)
    assert code == 143, output
    assert "vasc_pipeline: terminated (SIGTERM)" in output, output
    assert "Traceback" not in output, output
