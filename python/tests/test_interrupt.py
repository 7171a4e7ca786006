"""Ctrl-C stops a registration within moments, also during the long sampling of a large
cloud (the engine checks an interrupt flag between steps, not only between generations)."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

SCRIPT = """
import numpy as np, mtpcr, signal, sys
# Ctrl-C as at a terminal: a child of a shell's background job starts with SIGINT ignored, and
# Python then never raises KeyboardInterrupt.
signal.signal(signal.SIGINT, signal.default_int_handler)
rng = np.random.default_rng(0)
cloud = rng.normal(size=(400_000, 3))
print("ready", flush=True)
# Farthest-point sampling of half of 400k points takes minutes uninterrupted.
settings = dict(sample_ratio=0.5, max_sample_points=0, hypotheses=0, generations=8)
mtpcr.register(cloud, cloud[::2], **settings)
print("finished", flush=True)
"""


@pytest.mark.skipif(sys.platform == "win32", reason="SIGINT is a POSIX signal")
def test_ctrl_c_during_sampling_raises_keyboard_interrupt_at_once():
    proc = subprocess.Popen(
        [sys.executable, "-c", SCRIPT],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "ready"
    time.sleep(2.0)
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    waited = time.monotonic() - sent
    assert "finished" not in out
    assert "KeyboardInterrupt" in err, err
    assert waited < 5.0, f"the run went on for {waited:.1f} s after Ctrl-C"
