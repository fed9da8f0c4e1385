"""LearnerTeam's malloc setting: memory freed between minibatches is reused, not faulted in again from the kernel."""

from __future__ import annotations

import platform
import resource
import subprocess
import sys

import numpy as np
import pytest

from selfplay_cli.train.team import keep_freed_memory

# Six 4 MB blocks (every page written) allocated and freed ten times over, as an update's activations are: the
# minor page faults it takes.
ROUNDS = """
import resource, numpy as np
def rounds(n):
    for _ in range(n):
        blocks = [np.ones(1 << 20, dtype=np.float32) for _ in range(6)]
        del blocks
rounds(2)
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
rounds(10)
faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
"""


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="glibc's mallopt")
def test_freed_memory_is_kept_for_reuse():
    code = ROUNDS + "print(faults)"
    default = int(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)
    assert default > 10_000  # glibc's defaults: the 24 MB go back to the kernel and fault in again every round

    assert keep_freed_memory()
    scope: dict = {"np": np, "resource": resource}
    exec(ROUNDS, scope)
    assert scope["faults"] < 500
