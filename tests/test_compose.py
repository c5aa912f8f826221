"""docker/compose.yaml and docker/Dockerfile checked without a Docker engine: the services
exist, every command parses with the real command-line parsers, every link URL is valid and
points at the zenoh router's listener in client mode, and the image holds every package."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import pytest

yaml = pytest.importorskip("yaml", reason="pyyaml is in the [test] extra")

from vtolftc.cli.main import build_parser  # noqa: E402
from vtolftc.protocols import parse_link_url  # noqa: E402
from vtolftc.runners.processes import autopilot as ap_process  # noqa: E402
from vtolftc.runners.processes import vehicle as veh_process  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
COMPOSE = ROOT / "docker" / "compose.yaml"
DOCKERFILE = ROOT / "docker" / "Dockerfile"


@pytest.fixture(scope="module")
def compose() -> dict:
    return yaml.safe_load(COMPOSE.read_text())


def _router_endpoint(compose: dict) -> tuple[str, int]:
    cmd = compose["services"]["zenoh-router"]["command"]
    listen = cmd[cmd.index("-l") + 1]
    m = re.fullmatch(r"tcp/0\.0\.0\.0:(\d+)", listen)
    assert m, listen
    return "zenoh-router", int(m.group(1))


def _check_zenoh_url(url: str, compose: dict, direction: str, link: str) -> None:
    spec = parse_link_url(url)  # the project's own URL parser
    host, port = _router_endpoint(compose)
    assert spec.scheme == "zenoh" and spec.mode == "client"
    assert (spec.link, spec.direction) == (link, direction)
    assert spec.connect == (f"tcp/{host}:{port}",) and spec.listen == ()
    q = parse_qs(urlsplit(url).query)
    assert q["mode"] == ["client"]


def test_services_and_images(compose):
    services = compose["services"]
    assert {"vehicle", "autopilot", "dashboard", "zenoh-router"} <= set(services)
    assert services["zenoh-router"]["image"].startswith("eclipse/zenoh:")
    assert "--no-multicast-scouting" in services["zenoh-router"]["command"]
    for name in ("vehicle", "autopilot", "dashboard", "gcs"):
        svc = services[name]
        assert svc["build"] == {"context": "..", "dockerfile": "docker/Dockerfile"}
        assert (COMPOSE.parent / svc["build"]["context"] / svc["build"]["dockerfile"]).is_file()
        assert "zenoh-router" in svc["depends_on"]
    # published ports stay on the host's loopback
    for svc in services.values():
        for p in svc.get("ports", []):
            assert str(p).startswith("127.0.0.1:"), p


def test_router_version_matches_the_python_binding(compose):
    import importlib.metadata as md

    tag = compose["services"]["zenoh-router"]["image"].split(":", 1)[1].split()[0]
    assert tag.split(".")[:2] == md.version("eclipse-zenoh").split(".")[:2]


def test_vehicle_command_parses(compose):
    cmd = compose["services"]["vehicle"]["command"]
    assert cmd[:3] == ["python", "-m", "vtolftc.runners.processes.vehicle"]
    args = veh_process._parse_args(cmd[3:])
    assert args.lockstep is False and args.allow_remote
    _check_zenoh_url(args.link, compose, "up", "hil")


def test_autopilot_command_parses(compose):
    cmd = compose["services"]["autopilot"]["command"]
    assert cmd[:3] == ["python", "-m", "vtolftc.runners.processes.autopilot"]
    args = ap_process._parse_args(cmd[3:])
    assert args.lockstep is False and args.allow_remote and args.no_default_gcs
    _check_zenoh_url(args.hil_link, compose, "down", "hil")
    assert len(args.gcs_link) == 1
    _check_zenoh_url(args.gcs_link[0], compose, "up", "gcs")
    # the vehicle and the autopilot talk about the same vehicle
    veh = veh_process._parse_args(compose["services"]["vehicle"]["command"][3:])
    assert parse_link_url(veh.link).vehicle == parse_link_url(args.hil_link).vehicle


def test_dashboard_and_gcs_commands_parse(compose):
    parser = build_parser()
    dash = compose["services"]["dashboard"]["command"]
    assert dash[0] == "vtolftc"
    args = parser.parse_args(dash[1:])
    assert args.command == "dashboard" and args.host == "0.0.0.0"
    _check_zenoh_url(args.url, compose, "down", "gcs")
    published = compose["services"]["dashboard"]["ports"][0]
    assert published.endswith(f":{args.port}")
    gcs = compose["services"]["gcs"]
    argv = gcs["entrypoint"] + gcs["command"]
    args = parser.parse_args(argv[1:])
    assert args.command == "gcs" and args.allow_remote and args.gcs_command == "status"
    _check_zenoh_url(args.url, compose, "down", "gcs")


def test_dockerfile_copies_every_package():
    text = DOCKERFILE.read_text()
    py = tomllib.loads((ROOT / "pyproject.toml").read_text())
    packages = set(py["tool"]["setuptools"]["package-dir"].values())
    assert packages == {"vtolftc", "airframe", "firmware_sim", "gcs", "synthesis", "dashboard",
                        "protocols"}
    for pkg in sorted(packages):
        assert re.search(rf"^COPY {pkg} {pkg}$", text, re.M), f"{pkg} not copied"
        assert (ROOT / pkg).is_dir()
    assert "pip install ." in text
    assert "vtolftc.runners.processes.autopilot --help" in text
