"""Test helper: resume the session given as argument and record taps until killed, printing each
acknowledged tap id (after ``record_tap`` returned) on its own line."""

import sys

import numpy as np

from fixwizard.workflow.session import SamplingSession

MAX_TAPS = 100_000

if __name__ == "__main__":
    session = SamplingSession.open(sys.argv[1])
    for index in range(MAX_TAPS):
        base_T_tcp = np.eye(4)
        base_T_tcp[:3, 3] = [0.4, 0.001 * index, 0.2]
        tap = session.record_tap(base_T_tcp, force={"peak_n": 5.0})
        print(tap.id, flush=True)
