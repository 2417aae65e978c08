"""Security: MAVLink 2 signing end to end, Zenoh TLS / mTLS and access control on loopback,
loopback-only defaults.

The link-level cases (a rogue system on the controller's port, unsigned or wrongly signed
telemetry refused by the link) are in tests/integration/mavlink/; the vehicle-level ones
(unsigned commands refused, unsigned HEARTBEAT accepted) in test_vehicle_faults.py. Here the
whole chain runs as real processes.
"""
from __future__ import annotations

import datetime
import json
import socket
import threading
from pathlib import Path
from typing import Any

import pytest
import zenoh

from mission.mavlink import px4
from mission.bus.bridge import zenoh_config
from mission.config.schema import Config, MavlinkSection, ZenohSection
from mission.mavlink.link import DEFAULT_URL, VehicleLink
from mission.mavlink.env import mavlink
from sim.vehicle.mock import VehicleOptions
from sim.vehicle.cli import mock_vehicle
from tests.conftest import ROOT, free_port
from tests.faults.procs import SPEED, assert_log_complete, flight, wait_for

KEY = bytes.fromhex("5c1e" * 16)  # a throwaway 32-byte test key


# --------------------------------------------------------------------------------------------- MAVLink signing


def _tlog_packets(path: Path) -> list[bytes]:
    """Raw MAVLink 2 packets of a tlog (8-byte stamp + packet each)."""
    data, out, i = path.read_bytes(), [], 0
    while i + 8 + 12 <= len(data):
        i += 8
        assert data[i] == 0xFD, f"not a MAVLink 2 packet at byte {i}"
        size = 12 + data[i + 1] + (13 if data[i + 2] & 0x01 else 0)
        out.append(data[i:i + size])
        i += size
    return out


@pytest.mark.slow
@pytest.mark.timeout(90)
def test_signed_mission_flies_unsigned_commands_are_refused_and_the_key_is_never_logged(tmp_path: Path) -> None:
    key_file = tmp_path / "mavlink.key"
    key_file.write_text(KEY.hex() + "\n")
    # in lockstep, paced at the flight's speed so the ground station's attempts land while riding
    with flight(tmp_path, "signed", vehicle_args=("--signing-key", str(key_file), "--lockstep-max-speed", str(SPEED)),
                mission_args=("--signing-key", str(key_file)), mission_verbose=True, lockstep=True) as f:
        f.wait_phase("RIDING")
        gcs = f.gcs
        assert gcs is not None  # an unsigned ground station on the vehicle's (signed) GCS link
        # its unsigned HEARTBEATs are accepted: the vehicle sends it STATUSTEXT (PX4's rule)
        assert "Armed by external command" in [str(m.text) for m in gcs.messages("STATUSTEXT")]
        # an unsigned forced disarm in the air and unsigned setpoints are refused: no ACK
        mark = gcs.mark()
        for _ in range(5):
            gcs.send(mavlink.MAVLink_command_long_message(1, 1, px4.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0.0,
                                                          float(px4.ARM_FORCE_MAGIC), 0, 0, 0, 0, 0))
            gcs.send(gcs.setpoint_message((0.0, 0.0, 5.0)))
        assert gcs.wait_for("COMMAND_ACK", timeout_s=1.0, after=mark) is None
        wait_for(lambda: f.vehicle_counters()["unsigned"] >= 10, 10.0, "10 unsigned messages counted by the vehicle")
        f.wait_mission(40.0)
        assert f.procs["mission"].returncode == 0, f.text("mission.err")[-2000:]
        assert_log_complete(f, "DONE", None)
        assert f.vehicle()["armed"] and f.vehicle()["mode"] == "AUTO.LOITER"
        # everything the controller sent is signed (incompat flag 0x01 + 13-byte trailer)
        sent = [p for p in _tlog_packets(f.log_dir / "flight.tlog") if p[5:7] == bytes([1, 191])]
        assert len(sent) > 100 and all(p[2] & 0x01 for p in sent)
        # the key appears nowhere: process output, flight log, tlog
        needles = [KEY, KEY.hex().encode(), KEY.hex().upper().encode()]
        files = [p for p in f.dir.rglob("*") if p.is_file()]
        assert {p.name for p in files} >= {"mission.err", "mission.out", "vehicle.err", "record.csv", "summary.json",
                                           "flight.tlog", "mission.json"}
        for path in files:
            blob = path.read_bytes()
            assert not any(n in blob for n in needles), f"signing key found in {path.name}"


# --------------------------------------------------------------------------------------------- loopback defaults


def test_mavlink_and_zenoh_bind_to_loopback_by_default() -> None:
    assert DEFAULT_URL.startswith("udpin:127.0.0.1:")
    assert Config().mavlink.url == MavlinkSection().url == DEFAULT_URL
    bind = next(p for p in mock_vehicle.params if p.name == "mavlink_url").default
    target = next(p for p in mock_vehicle.params if p.name == "target_url").default
    assert bind == "udpin:127.0.0.1:14580" and target == "udpout:127.0.0.1:14540"
    assert VehicleOptions().bind.startswith("127.0.0.1:") and VehicleOptions().gcs_bind.startswith("127.0.0.1:")
    with VehicleLink("udpin:127.0.0.1:0") as link:
        assert link.port
    # Zenoh: every mode's default endpoints are loopback, multicast scouting off; a peer given
    # only a router to connect to listens on loopback too (not Zenoh's tcp/[::]:0 default).
    for section in (ZenohSection(), ZenohSection(mode="router"), ZenohSection(mode="client"),
                    ZenohSection(connect=["tcp/127.0.0.1:9"]), ZenohSection(rendezvous=None)):
        conf = zenoh_config(section)
        assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
        listen = json.loads(conf.get_json("listen/endpoints"))
        if isinstance(listen, dict):  # Zenoh's per-mode defaults: a client has none (it never listens)
            assert section.mode == "client" and listen.get("client") is None, listen
            listen = []
        endpoints = [*listen, *json.loads(conf.get_json("connect/endpoints"))]
        assert endpoints and all(e.startswith("tcp/127.0.0.1:") for e in endpoints), (section, endpoints)
    assert json.loads(zenoh_config(ZenohSection(connect=["tcp/127.0.0.1:9"])).get_json("listen/endpoints")) == \
        ["tcp/127.0.0.1:0"]


# --------------------------------------------------------------------------------------------- Zenoh TLS and ACL

x509 = pytest.importorskip("cryptography.x509", reason="the cryptography package makes the throwaway CA")


def _certs(directory: Path) -> dict[str, str]:
    """A throwaway CA, a router certificate for 127.0.0.1/localhost, client certificates
    (CN pair0-carrier, pair0-passenger, rogue) and one from an untrusted CA; PEM paths."""
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID
    import ipaddress

    now = datetime.datetime.now(datetime.timezone.utc)
    paths: dict[str, str] = {}

    def name(cn: str) -> Any:
        return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)])

    def write(label: str, key: Any, cert: Any) -> None:
        (directory / f"{label}-key.pem").write_bytes(key.private_bytes(
            serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()))
        (directory / f"{label}.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))
        paths[label], paths[f"{label}-key"] = str(directory / f"{label}.pem"), str(directory / f"{label}-key.pem")

    def ca(label: str) -> tuple[Any, Any]:
        key = ec.generate_private_key(ec.SECP256R1())
        cert = (x509.CertificateBuilder().subject_name(name(label)).issuer_name(name(label)).public_key(key.public_key())
                .serial_number(x509.random_serial_number()).not_valid_before(now - datetime.timedelta(minutes=5))
                .not_valid_after(now + datetime.timedelta(days=1))
                .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
                .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True, content_commitment=False,
                                             key_encipherment=False, data_encipherment=False, key_agreement=False,
                                             encipher_only=False, decipher_only=False), critical=True)
                .sign(key, hashes.SHA256()))
        write(label, key, cert)
        return key, cert

    def leaf(label: str, cn: str, issuer: tuple[Any, Any], server: bool) -> None:
        key = ec.generate_private_key(ec.SECP256R1())
        san = [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))] if server else [x509.DNSName(cn)]
        usage = x509.oid.ExtendedKeyUsageOID.SERVER_AUTH if server else x509.oid.ExtendedKeyUsageOID.CLIENT_AUTH
        cert = (x509.CertificateBuilder().subject_name(name(cn)).issuer_name(issuer[1].subject).public_key(key.public_key())
                .serial_number(x509.random_serial_number()).not_valid_before(now - datetime.timedelta(minutes=5))
                .not_valid_after(now + datetime.timedelta(days=1))
                .add_extension(x509.SubjectAlternativeName(san), critical=False)
                .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
                .add_extension(x509.ExtendedKeyUsage([usage]), critical=False)
                .sign(issuer[0], hashes.SHA256()))
        write(label, key, cert)

    fleet_ca = ca("ca")
    leaf("router", "router", fleet_ca, server=True)
    for label in ("pair0-carrier", "pair0-passenger", "rogue"):
        leaf(label, label, fleet_ca, server=False)
    leaf("stranger", "pair0-carrier", ca("other-ca"), server=False)  # right name, wrong CA
    return paths


@pytest.fixture(scope="module")
def certs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    return _certs(tmp_path_factory.mktemp("certs"))


def _router(port: int, certs: dict[str, str], mtls: bool, acl: dict[str, Any] | None = None) -> zenoh.Session:
    conf: dict[str, Any] = {
        "mode": "router", "listen": {"endpoints": [f"tls/127.0.0.1:{port}"]}, "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {"tls": {"root_ca_certificate": certs["ca"], "listen_private_key": certs["router-key"],
                                       "listen_certificate": certs["router"], "enable_mtls": mtls}}},
    }
    if acl is not None:
        conf["access_control"] = acl
    return zenoh.open(zenoh.Config.from_json5(json.dumps(conf)))


def _client(port: int, certs: dict[str, str], identity: str | None, ca: str = "ca") -> zenoh.Session:
    tls: dict[str, Any] = {"root_ca_certificate": certs[ca]}
    if identity is not None:
        tls.update(enable_mtls=True, connect_private_key=certs[f"{identity}-key"], connect_certificate=certs[identity])
    conf = {"mode": "client", "connect": {"endpoints": [f"tls/127.0.0.1:{port}"]},
            "scouting": {"multicast": {"enabled": False}}, "transport": {"link": {"tls": tls}}}
    return zenoh.open(zenoh.Config.from_json5(json.dumps(conf)))


def _delivered(pub_session: zenoh.Session, sub_session: zenoh.Session, key: str, n: int = 3, *,
               denied: bool = False) -> int:
    """How many of ``n`` puts on ``key`` reach a subscriber, counted once a trailing marker arrived.

    Zenoh keeps the order of one publisher's puts on one key, not across keys (measured: a put on
    one key overtook the put before it on another in 915 of 2000 tries), so the marker of an
    allowed key goes on that key. On a ``denied`` key the marker could not pass, so it goes on
    another key: the count can then only err towards "delivered" late, never towards a false 0
    for puts that the router let through (they would arrive at some point and be counted by a
    later call). Both routes are matched before anything is put (puts with no known subscriber
    are dropped at the source; the ACL acts on puts, not on declarations, so a denied key matches).
    """
    got: list[bytes] = []
    done = threading.Event()
    marker_key = "marsupial/test/marker" if denied else key

    def on_sample(sample: zenoh.Sample) -> None:
        payload = sample.payload.to_bytes()
        (done.set() if payload == b"marker" else got.append(payload))

    subs = [sub_session.declare_subscriber(k, on_sample) for k in dict.fromkeys((key, marker_key))]
    try:
        pub = pub_session.declare_publisher(key)
        marker = pub_session.declare_publisher(marker_key) if denied else pub
        try:
            wait_for(lambda: marker.matching_status.matching and pub.matching_status.matching, 10.0, "subscribers matched")
            for i in range(n):
                pub.put(f"state {i}".encode())
            marker.put(b"marker")
            wait_for(lambda: done.wait(0.05), 10.0, "marker delivered")
        finally:
            pub.undeclare()
            if denied:
                marker.undeclare()
    finally:
        for sub in subs:
            sub.undeclare()
    return len(got)


@pytest.mark.timeout(60)
def test_zenoh_tls_and_mtls_carry_pub_sub_and_refuse_clients_without_the_right_certificate(certs: dict[str, str]) -> None:
    key = "marsupial/pair0/carrier/state"
    # TLS: the client checks the router's certificate (CA + name), no client certificate
    port = free_port(socket.SOCK_STREAM)
    router = _router(port, certs, mtls=False)
    try:
        a, b = _client(port, certs, None), _client(port, certs, None)
        try:
            assert _delivered(a, b, key) == 3
        finally:
            a.close()
            b.close()
        with pytest.raises(zenoh.ZError):  # a client that does not trust the router's CA
            _client(port, certs, None, ca="other-ca")
    finally:
        router.close()
    # mTLS: the router demands a client certificate signed by the fleet CA
    port = free_port(socket.SOCK_STREAM)
    router = _router(port, certs, mtls=True)
    try:
        a, b = _client(port, certs, "pair0-carrier"), _client(port, certs, "pair0-passenger")
        try:
            assert _delivered(a, b, key) == 3
        finally:
            a.close()
            b.close()
        for identity in (None, "stranger"):  # no certificate; the right name from another CA
            with pytest.raises(zenoh.ZError):
                _client(port, certs, identity)
    finally:
        router.close()


@pytest.mark.timeout(60)
def test_zenoh_access_control_denies_a_subject_the_carrier_state_key(certs: dict[str, str]) -> None:
    """ACL on the router, subjects by certificate common name (mTLS): "rogue" may not put on
    the carrier state key of pair0, whatever else it does; the carrier may."""
    acl = {
        "enabled": True, "default_permission": "allow",
        "rules": [{"id": "no-carrier-state", "permission": "deny", "flows": ["ingress"], "messages": ["put"],
                   "key_exprs": ["marsupial/pair0/carrier/state"]}],
        "subjects": [{"id": "rogue", "cert_common_names": ["rogue"]}],
        "policies": [{"rules": ["no-carrier-state"], "subjects": ["rogue"]}],
    }
    port = free_port(socket.SOCK_STREAM)
    router = _router(port, certs, mtls=True, acl=acl)
    try:
        rogue, carrier, passenger = (_client(port, certs, who) for who in ("rogue", "pair0-carrier", "pair0-passenger"))
        try:
            assert _delivered(rogue, passenger, "marsupial/pair0/carrier/state", denied=True) == 0
            assert _delivered(rogue, passenger, "marsupial/pair0/passenger/phase") == 3  # another key: allowed
            assert _delivered(carrier, passenger, "marsupial/pair0/carrier/state") == 3  # the carrier: allowed
        finally:
            for s in (rogue, carrier, passenger):
                s.close()
    finally:
        router.close()


@pytest.mark.timeout(60)
def test_default_deny_router_acl_example_lets_each_robot_speak_only_for_its_own_side(certs: dict[str, str]) -> None:
    """configs/zenoh/router_acl_example.json5, as shipped, on an mTLS router: the carrier and the
    passenger of pair0 reach each other; a "rogue" certificate of the same fleet CA that may watch
    pair0 (a ground station's, say: pair0-listen only) cannot publish either side's state, and
    neither robot can publish the other's. The test adds one allowed marker key per subject, which
    _delivered's counting of denied puts needs."""
    acl = json.loads(zenoh.Config.from_file(str(ROOT / "configs/zenoh/router_acl_example.json5")).get_json("access_control"))
    assert acl["enabled"] and acl["default_permission"] == "deny"
    acl["rules"].append({"id": "test-marker", "permission": "allow", "flows": ["ingress", "egress"],
                         "messages": ["put", "declare_subscriber"], "key_exprs": ["marsupial/test/**"]})
    acl["subjects"].append({"id": "rogue", "cert_common_names": ["rogue"]})
    acl["policies"].append({"rules": ["pair0-listen", "pair0-deliver"], "subjects": ["rogue"]})
    for policy in acl["policies"]:
        policy["rules"].append("test-marker")
    port = free_port(socket.SOCK_STREAM)
    router = _router(port, certs, mtls=True, acl=acl)
    try:
        rogue, carrier, passenger = (_client(port, certs, who) for who in ("rogue", "pair0-carrier", "pair0-passenger"))
        try:
            assert _delivered(carrier, passenger, "marsupial/pair0/carrier/state") == 3
            assert _delivered(passenger, carrier, "marsupial/pair0/passenger/state") == 3
            assert _delivered(passenger, carrier, "marsupial/pair0/passenger/phase") == 3
            assert _delivered(rogue, passenger, "marsupial/pair0/carrier/state", denied=True) == 0
            assert _delivered(rogue, carrier, "marsupial/pair0/passenger/phase", denied=True) == 0
            assert _delivered(carrier, passenger, "marsupial/pair0/passenger/phase", denied=True) == 0
            assert _delivered(passenger, carrier, "marsupial/pair0/carrier/state", denied=True) == 0
        finally:
            for s in (rogue, carrier, passenger):
                s.close()
    finally:
        router.close()
