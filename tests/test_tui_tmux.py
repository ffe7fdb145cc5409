"""The smoke test as a person runs it: `fixwizard` in an 80x24 terminal (tmux), keys sent, the screen read back.
Once with 256 colours and once with NO_COLOR."""

import shlex
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

pytestmark = [pytest.mark.skipif(shutil.which("tmux") is None,
                                 reason="tmux is not installed; `./dev test` installs it with apt-get"),
              pytest.mark.slow]  # the real wizard started in a terminal, about 12 s a run

FIXWIZARD = Path(sys.executable).parent / "fixwizard"


class Terminal:
    """An 80x24 tmux session on a private server (its socket in ``folder``), running one command in ``folder``."""

    def __init__(self, folder: Path, command: str, env: dict[str, str]) -> None:
        self.tmux = ["tmux", "-S", str(folder / "tmux.socket")]
        settings = [arg for name, value in env.items() for arg in ("-e", f"{name}={value}")]
        subprocess.run([*self.tmux, "-f", "/dev/null", "new-session", "-d", "-s", "wizard", "-x", "80", "-y", "24",
                        "-c", str(folder), *settings, command], check=True)

    def screen(self) -> str:
        return subprocess.run([*self.tmux, "capture-pane", "-p", "-t", "wizard"], check=True, capture_output=True,
                              text=True).stdout

    def send(self, *keys: str) -> None:
        subprocess.run([*self.tmux, "send-keys", "-t", "wizard", *keys], check=True)

    def wait_for(self, condition: Callable[[str], bool], timeout_s: float = 30.0) -> str:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            screen = self.screen()
            if condition(screen):
                return screen
            time.sleep(0.2)
        raise AssertionError(f"the terminal never showed what was expected; it shows:\n{self.screen()}")

    def close(self) -> None:
        subprocess.run([*self.tmux, "kill-server"], check=False, capture_output=True)


def bottom_line(screen: str) -> str:
    lines = screen.splitlines()
    return lines[-1] if lines else ""


@pytest.mark.parametrize("env", [{"TERM": "xterm-256color"}, {"TERM": "xterm-256color", "NO_COLOR": "1"}],
                         ids=["256-colours", "NO_COLOR"])
def test_fixwizard_in_a_terminal_shows_the_start_screen_stops_and_quits(tmp_path, env):
    exit_file = tmp_path / "exit-status"
    command = f"{shlex.quote(str(FIXWIZARD))}; echo $? > {shlex.quote(str(exit_file))}; sleep 60"
    terminal = Terminal(tmp_path, command, env)
    try:
        screen = terminal.wait_for(lambda text: "160.0 x 90.0 x 60.0 mm" in text and "F12 STOP" in bottom_line(text))
        lines = screen.splitlines()
        assert lines[0].startswith(" SIMULATED  demo cell (seed 0) | connected | idle | F12 STOP")
        assert "Start: choose the fixture and the tip calibration" in screen and "Continue" in screen
        terminal.send("F12")
        terminal.wait_for(lambda text: "STOP sent: the robot halts" in text)
        terminal.send("C-q")
        terminal.wait_for(lambda text: exit_file.exists(), timeout_s=10)
        assert exit_file.read_text().strip() == "0"
        after = terminal.screen()  # the terminal's own screen again, as it was while the wizard loaded
        assert "Traceback" not in after
        assert "Starting the wizard: loading the fixtures and the solver" in after  # with dots: no blank wait
    finally:
        terminal.close()
