"""The same capture through all four doors gives identical blocks.

Doors: ``usbsim://`` (pyusb core over SimUsbBackend), ``sim://`` (pyserial handler, in-process),
``socket://`` to a ``python -m simulator serve --tcp 127.0.0.1:0`` process, and the pty of a
``python -m simulator serve --pty`` process. Each runs the real ``acquisition.driver.Analyser``:
configure the default set-up, capture two blocks.
"""
from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from acquisition.driver import Analyser
from acquisition.setup import default_setup

ROOT = Path(__file__).resolve().parents[1]
SEED = 5


def _start(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "simulator", "serve", *args, "--seed", str(SEED)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _url(proc: subprocess.Popen) -> str:
    """The URL the started server prints once it listens."""
    url = proc.stdout.readline().strip()
    if not url:
        proc.kill()
        pytest.fail(f"the server printed no URL: {proc.communicate(timeout=10)[1]}")
    return url


def _shutdown(proc: subprocess.Popen) -> int:
    proc.send_signal(signal.SIGTERM)
    try:
        return proc.wait(timeout=5)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.stdout.close()
        proc.stderr.close()


@pytest.fixture(scope="module")
def servers():
    tcp, pty = _start("--tcp", "127.0.0.1:0"), _start("--pty")    # both start at once (each waits for its imports)
    try:
        tcp_url, pty_path = _url(tcp), _url(pty)
    except BaseException:
        for proc in (tcp, pty):
            proc.kill()
            proc.communicate(timeout=10)
        raise
    yield {"socket": tcp_url, "pty": pty_path}
    assert _shutdown(tcp) == 0
    assert _shutdown(pty) == 0


def _capture_two(url: str):
    with Analyser(url, timeout_s=10.0) as analyser:
        analyser.configure(default_setup())
        blocks = [analyser.capture(timeout_s=10.0) for _ in range(2)]
    return blocks


@pytest.fixture(scope="module")
def reference():
    return _capture_two(f"sim://?seed={SEED}")


def test_reference_capture_is_meaningful(reference) -> None:
    setup = default_setup()
    a, b = reference
    assert a.counts.shape == (4, setup.block_size) and a.counts.dtype == np.int16
    assert a.trigger_index == setup.trigger.pretrigger_samples
    # the force crosses the 20 N trigger level right at the trigger index
    assert a.data[0, a.trigger_index] >= 20.0 > a.data[0, a.trigger_index - 1]
    assert not np.array_equal(a.counts, b.counts)  # two different hits
    assert (a.sequence, b.sequence) == (1, 2)


@pytest.mark.parametrize("door", ["usbsim", "socket", "pty"])
def test_door_gives_identical_blocks(door: str, reference, servers) -> None:
    url = {"usbsim": f"usbsim://?seed={SEED}", **servers}[door]
    blocks = _capture_two(url)
    for got, ref in zip(blocks, reference):
        np.testing.assert_array_equal(got.counts, ref.counts)
        np.testing.assert_array_equal(got.volts_per_count, ref.volts_per_count)
        np.testing.assert_array_equal(got.overload, ref.overload)
        assert (got.trigger_index, got.sequence, got.sample_rate_hz, got.device_time_s) == (
            ref.trigger_index, ref.sequence, ref.sample_rate_hz, ref.device_time_s)


def test_another_seed_gives_other_blocks(reference) -> None:
    # "identical" above means something: the blocks depend on the seed
    other = _capture_two(f"sim://?seed={SEED + 1}")
    assert not np.array_equal(other[0].counts, reference[0].counts)
