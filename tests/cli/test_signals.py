"""SIGTERM and SIGHUP during a run: one line naming the signal, the shell's status, nothing written."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mpcform.cli.signals import Terminated, terminating

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_signal_during_a_run_is_one_line_and_128_plus_its_number(tmp_path: Path, sig: int) -> None:
    swap, out = str(ROOT / "scenarios" / "swap_spatial_20.toml"), str(tmp_path / "out")
    run = f"sys.exit(main(['run', {swap!r}, '--out', {out!r}]))"
    code = f"import sys; from mpcform.cli.main import main; print('ready', flush=True); {run}"
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stdout.readline() == b"ready\n"  # imported
    time.sleep(1.5)  # inside the run (it plans for a minute)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    name = signal.Signals(sig).name
    assert proc.returncode == 128 + sig and err.decode().strip().splitlines() == [
        f"mpcform: interrupted ({name})"
    ]
    assert not (tmp_path / "out" / "trajectory.npz").exists()  # a run writes only once it is done


def test_the_handlers_are_restored_after_the_block() -> None:
    before = signal.getsignal(signal.SIGTERM)
    with terminating(), pytest.raises(Terminated) as caught:
        signal.raise_signal(signal.SIGTERM)
    assert caught.value.name == "SIGTERM" and isinstance(caught.value, KeyboardInterrupt)
    assert signal.getsignal(signal.SIGTERM) is before
