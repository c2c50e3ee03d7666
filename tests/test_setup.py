"""The default set-up's record length comes from the physics: the slowest-decaying mode of the
simulated frame's default band decays by DEFAULT_DECAY_DB within the record; the set-up prints as
a TOML template that --setup reads back."""
from __future__ import annotations

import math

import numpy as np
import pytest
import tomllib

from acquisition import cli_capture
from acquisition.errors import SetupError
from acquisition.setup import (
    DEFAULT_DECAY_DB,
    DEFAULT_SLOWEST_MODE,
    AcquisitionSetup,
    block_size_for_decay,
    default_setup,
    load_setup,
    setup_to_toml,
)
from analysis.modal import decay_time_s


def test_decay_time_and_block_size():
    tau = 1 / (0.01 * 2 * math.pi * 10.0)  # 1.59 s
    assert decay_time_s(10.0, 0.01, 20 * math.log10(math.e)) == pytest.approx(tau)  # one time constant: 8.69 dB
    assert decay_time_s(10.0, 0.01, 40.0) == pytest.approx(tau * math.log(100))
    # 1.59 s x ln(100) = 7.33 s at 1000 Hz: 7330 samples (+ 100 pre-trigger) -> 8192
    assert block_size_for_decay(1000.0, 10.0, 0.01, decay_db=40.0, pretrigger_samples=100) == 8192
    assert block_size_for_decay(1000.0, 10.0, 0.01, decay_db=40.0, pretrigger_samples=900) == 16384
    with pytest.raises(SetupError, match="lower the sample rate or use an exponential window"):
        block_size_for_decay(51200.0, 1.0, 0.001)
    with pytest.raises(ValueError, match="positive"):
        decay_time_s(10.0, 0.0, DEFAULT_DECAY_DB)
    with pytest.raises(SetupError, match="positive"):
        block_size_for_decay(1000.0, 10.0, 0.0)


def test_the_slowest_mode_and_the_record_it_needs():
    """The frame's modes (simulator, the truth) below the default band's top: the one with the longest
    decay is DEFAULT_SLOWEST_MODE; block_size_for_decay gives the shortest record that holds its decay
    by DEFAULT_DECAY_DB, and the default record (1.28 s) is shorter than that (its peak leaks: the
    docstring of default_setup says so)."""
    from simulator.config import FrameConfig
    from simulator.fem import FrameModel

    cfg = FrameConfig.load(None)
    modes = FrameModel.from_config(cfg).modes(1100.0)
    wn = np.abs(modes.poles)
    zeta = -modes.poles.real / wn
    slow = int(np.argmin(zeta * wn))
    assert wn[slow] / (2 * np.pi) == pytest.approx(DEFAULT_SLOWEST_MODE[0], rel=0.02)
    assert zeta[slow] == pytest.approx(DEFAULT_SLOWEST_MODE[1], rel=0.05)
    s = default_setup()
    block = block_size_for_decay(s.sample_rate_hz, *DEFAULT_SLOWEST_MODE, pretrigger_samples=s.trigger.pretrigger_samples)
    need = math.log(10 ** (DEFAULT_DECAY_DB / 20)) / (zeta[slow] * wn[slow])
    assert (block - s.trigger.pretrigger_samples) / s.sample_rate_hz >= need
    assert (block / 2 - s.trigger.pretrigger_samples) / s.sample_rate_hz < need
    assert block == 32768 and s.block_size == 8192
    # the default 1.28 s record keeps about half of that mode's amplitude at its end
    assert math.exp(-(s.block_size - 128) / 6400 * zeta[slow] * wn[slow]) > 0.4


def test_print_setup_is_a_template_that_setup_reads_back(tmp_path, capsys):
    assert cli_capture.main(["--print-setup"]) == 0
    text = capsys.readouterr().out
    assert AcquisitionSetup.from_dict(tomllib.loads(text)) == default_setup()
    path = tmp_path / "mine.toml"
    path.write_text(text.replace("level = 20.0", "level = 35.0"))
    assert load_setup(path).trigger.level == 35.0
    assert cli_capture.main(["--print-setup", "--setup", str(path)]) == 0
    assert "level = 35.0" in capsys.readouterr().out
    assert setup_to_toml(default_setup()).startswith("# impact test set-up")
