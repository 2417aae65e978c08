"""A rogue Zenoh peer in a process of its own, for tests: ``python -m tests.support.zenoh_rogue
ENDPOINT KEY...`` opens a peer session connected to ENDPOINT (loopback, no multicast), declares a
liveliness token on each KEY, prints ``ready``, and when its stdin ends closes the session, still
holding the tokens, and exits. In a process of its own its session shares no Zenoh runtime with
the test's sessions: a rogue that goes away is gone from the wire, and the others hear it by its
close or, at the latest, by its lease."""
from __future__ import annotations

import sys

from tests.support.zenoh_util import peer


def main(argv: list[str]) -> None:
    ep, keys = argv[0], argv[1:]
    session = peer(connect=[ep])
    tokens = [session.liveliness().declare_token(k) for k in keys]
    print("ready", flush=True)
    sys.stdin.read()
    session.close()
    del tokens


if __name__ == "__main__":
    main(sys.argv[1:])
