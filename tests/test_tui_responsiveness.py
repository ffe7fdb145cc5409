"""The wizard's event loop never waits on the solver: while the live check and the full solve run in their
process, the loop's 10 ms timer runs on time and a key is answered at once (bounds generous enough for a loaded
test machine; benchmarks/responsiveness.py prints the real numbers)."""

import pytest

from loop_lag import measure_wizard

pytestmark = pytest.mark.asyncio
MAX_LAG_S = 0.5


async def test_keys_are_answered_and_the_loop_runs_on_time_during_the_live_check_and_the_solve(tmp_path):
    measured = await measure_wizard(tmp_path, taps=6, max_cells=1e6)
    assert measured.key_s < MAX_LAG_S
    assert len(measured.lags_s["live"]) > 10 and len(measured.lags_s["solve"]) > 10
    assert max(measured.lags_s["live"]) < MAX_LAG_S
    assert max(measured.lags_s["solve"]) < MAX_LAG_S
