"""The demo's console while its missions fly (``marsupial demo``, one pair, several, or a team):
a progress bar per mission on a terminal, plain phase lines otherwise, and the wait for every
mission to end within the demo's wall-clock limit."""
from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from contextlib import ExitStack
from collections.abc import Sequence
from typing import Any

from tqdm import tqdm

from mission.phases import Phase

PHASE_STEPS = [(p.value,) for p in Phase if p not in (Phase.ABORT, Phase.HOLD, Phase.LAND, Phase.DONE)] + [
    (Phase.HOLD.value, Phase.LAND.value), (Phase.DONE.value,)]



def phase_step(phase: str) -> int | None:
    """1-based step of ``phase`` on the nominal path (HOLD and LAND are the same step), or None
    for ABORT or an unknown name."""
    for i, names in enumerate(PHASE_STEPS, start=1):
        if phase in names:
            return i
    return None


class PairProgress:
    """The demo's live display: one bar per pair on a terminal, whose count never goes back
    (a phase skipped, e.g. ARMING when already armed, jumps forward; an abort leaves the bar
    where it was and names the reason); plain ``pair: line`` phase lines otherwise."""

    def __init__(self, names: list[str], tty: bool, out=None) -> None:
        self.tty, self.out = tty, out or sys.stdout
        self._lock = threading.Lock()
        self.steps: dict[str, int] = {n: 0 for n in names}
        self.bars: dict[str, tqdm] = {}
        if tty:
            width = max(len(n) for n in names)
            for i, name in enumerate(names):
                self.bars[name] = tqdm(total=len(PHASE_STEPS), desc=f"{name:<{width}}", position=i, file=self.out,
                                       leave=True, bar_format="{desc} {n_fmt}/{total_fmt} |{bar:20}| {elapsed}{postfix}")

    def update(self, pair: str, phase: str, line: str) -> None:
        with self._lock:
            step = phase_step(phase)
            if step is not None:
                self.steps[pair] = max(self.steps[pair], step)
            if not self.tty:
                self.out.write(f"{pair}: {line}\n")
                self.out.flush()
                return
            bar = self.bars[pair]
            bar.n = self.steps[pair]
            bar.set_postfix_str(phase if step is not None else line.split("] ", 1)[-1], refresh=False)
            bar.refresh()

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()


def follow_mission(pair: Any, progress: PairProgress) -> None:
    """Read the mission's stdout: phase lines move the pair's progress."""
    stream = pair.procs["mission"].stdout
    assert stream is not None
    for raw in stream:
        line = raw.rstrip()
        pair.lines.append(line)
        if "] phase " in line:
            phase = line.split("] phase ", 1)[1].split()[0]
            pair.phase = phase
            progress.update(pair.name, phase, line.strip())


def watch_missions(runs: Sequence[Any], timeout_s: float, progress: bool, stack: ExitStack) -> list[threading.Thread]:
    """Show every run's mission (``run.name``, ``run.procs["mission"]`` with its stdout piped) on
    the console, and wait until each has ended, at most ``timeout_s`` [s] of wall time in all; a
    mission still flying then is sent SIGINT (what Ctrl-C does: it holds, then exits). Returns the
    threads reading their output, for the caller to join once the processes are stopped."""
    display = PairProgress([r.name for r in runs], tty=progress and sys.stdout.isatty())
    stack.callback(display.close)
    readers = [threading.Thread(target=follow_mission, args=(r, display), daemon=True) for r in runs]
    for reader in readers:
        reader.start()
    deadline = time.monotonic() + timeout_s
    for r in runs:
        try:
            r.procs["mission"].wait(timeout=max(deadline - time.monotonic(), 0.1))
        except subprocess.TimeoutExpired:
            r.procs["mission"].send_signal(signal.SIGINT)
    return readers
