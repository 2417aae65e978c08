"""Late but authentic carrier states on the landing: a keyless relay between two Zenoh routers
forwards the carrier's real, signed states 0.45 s or 1.5 s late, in order, from the moment the
passenger turns home (:mod:`tests.faults.relay`), on the real processes of a pair in lockstep.
The passenger lands on the deck of a carrier driving on at 1.5 m/s (configs/cycle.toml with its
first target only); the mock's deck follows the true carrier (router A) and records where the
passenger touched it (``mock-vehicle --summary``).

- 0.45 s: a go-around, or a dock within 0.10 m of the deck's true centre; never a crash.
- 1.5 s: a safe fallback (Hold off the carrier's path), no touchdown.
In both the mission's summary agrees with the deck.
"""
from __future__ import annotations

import json
import secrets
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import CONFIGS
from tests.faults.procs import Router, assert_safe_end, flight
from tests.faults.relay import DelayRelay

pytestmark = [pytest.mark.slow, pytest.mark.timeout(240)]
# A class per test: `--dist loadscope` schedules a class as its own unit, so the two flights spread over the workers.

CYCLE = CONFIGS / "cycle.toml"
DECK_HEIGHT_M = 0.5  # configs/cycle.toml: the deck, 0.5 m above the carrier's reported position


def _config(tmp_path: Path) -> Path:
    text = CYCLE.read_text()
    both = "targets = [[24.0, 18.0, -5.0], [44.0, 4.0, -4.0]]"
    assert both in text
    path = tmp_path / "deck_landing.toml"
    path.write_text(text.replace(both, "targets = [[24.0, 18.0, -5.0]]"))
    return path


def _key(tmp_path: Path) -> tuple[Path, bytes]:
    key = secrets.token_bytes(32)
    path = tmp_path / "bus.key"
    path.write_text(key.hex() + "\n")
    path.chmod(0o600)
    return path, key


def fly_delayed(tmp_path: Path, delay_s: float) -> dict[str, Any]:
    """Fly the deck landing with the carrier's states ``delay_s`` late from RETURNING on; the
    mission's summary, the deck's truth and the relay's figures."""
    key_file, key = _key(tmp_path)
    a, b = Router(), Router()
    relay = DelayRelay(a.session, b.session, "pair0", delay_s, key)
    truth_path = tmp_path / "vehicle.json"
    signed = ("--zenoh-signing-key", str(key_file))
    try:
        with flight(tmp_path, f"delay{delay_s:g}", router=a, mission_router=b, config=_config(tmp_path),
                    lockstep=True, carrier_args=signed, mission_args=signed,
                    vehicle_args=("--start-ned", f"0,0,{-DECK_HEIGHT_M}", "--deck", "pair0", "--deck-height",
                                  str(DECK_HEIGHT_M), "--zenoh-connect", a.endpoint, "--summary", str(truth_path))) as f:
            code = f.wait_mission(200.0)
            summary = f.summary()
            phases = f.phases()
            if summary.get("phase") == "DONE" and phases[-2:-1] == ["HOLD"]:
                assert_safe_end(f, modes=("AUTO.LOITER",))
        truth = json.loads(truth_path.read_text())
    finally:
        relay.close()
        a.close()
        b.close()
    return {"code": code, "summary": summary, "phases": phases, "deck": truth["deck"],
            "relay": {"active_at_s": relay.active_at_s, "max_delay_s": relay.max_delay_s, "released": relay.released}}


def _report(out: dict[str, Any]) -> str:
    s = out["summary"]
    return json.dumps({"code": out["code"], "phases": out["phases"], "deck": out["deck"], "relay": out["relay"],
                       "outcome": s.get("recovery_outcome"), "contact": s.get("contact"),
                       "phase": s.get("phase"), "reason": s.get("reason")}, indent=1, default=str)


class TestLate045:
    def test_states_late_by_045_s_on_the_landing_never_crash(self, tmp_path: Path) -> None:
        out = fly_delayed(tmp_path, 0.45)
        print(_report(out))
        deck, s = out["deck"], out["summary"]
        assert out["relay"]["max_delay_s"] >= 0.45 - 1e-6, out["relay"]
        feed = s["carrier_feed"]
        assert feed["delay_growths"] >= 1 and "0.4" in feed["delay_growth_last"], feed  # the growing delay, named
        assert deck["crash"] is None, _report(out)
        if s.get("docked_again"):
            assert deck["touchdowns"], _report(out)
            assert deck["touchdowns"][-1]["horizontal_error_m"] <= 0.10, _report(out)
        else:  # the approach went around, or was refused, on states older than its budget; then a safe fallback
            assert out["code"] == 0 and out["phases"][-3:] == ["FALLBACK", "HOLD", "DONE"], _report(out)
            assert "approaches without docking" in s["recovery_outcome"] and "carrier_max_age_s" in s["recovery_outcome"], \
                _report(out)
        assert not deck["touchdowns"][1:] or s.get("docked_again"), _report(out)  # the deck agrees with the summary


class TestLate15:
    def test_states_late_by_15_s_on_the_landing_fall_back(self, tmp_path: Path) -> None:
        out = fly_delayed(tmp_path, 1.5)
        print(_report(out))
        deck, s = out["deck"], out["summary"]
        assert deck["crash"] is None, _report(out)
        assert not s.get("docked_again"), _report(out)
        assert str(s.get("recovery_outcome", "")).startswith("fallback"), _report(out)
        assert not deck["touchdowns"][1:], _report(out)  # the deck agrees: never touched after the start
