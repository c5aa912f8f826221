"""A wheel install, as a user gets it: ``pip install .`` (not editable) into a fresh virtual
environment, then the README's first command and a SITL flight run from outside the checkout by
a user who cannot write to site-packages (so nothing may be generated there at run time).

The wheel venv borrows the dependencies of the environment that runs the tests (a ``.pth``
file naming that environment's site-packages directories, after the venv's own), so that the
test does not download numba and scipy again and works from a virtual environment as well as
from a system Python: ``--system-site-packages`` would reach only the *base* interpreter's
packages, which a venv user does not have. The directories are added as plain paths, so their
``.pth`` files (the editable install of this checkout among them) are not run: the project
itself comes only from the wheel, which the test checks by asking where every ``vtolftc``
package was imported from.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow


def _tracked_copy(dst: Path) -> None:
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True,
                           check=True).stdout.decode().split("\0")
    for rel in filter(None, files):
        src = ROOT / rel
        if src.is_file():
            (dst / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst / rel)


def _site_read_only(site: Path, cmd: list[str]) -> list[str]:
    """``cmd`` with site-packages read-only: as root (who writes anywhere) inside a private mount
    namespace with the venv's site-packages bind-mounted read-only; otherwise the fixture has
    taken the write bits away."""
    if os.geteuid() == 0:
        return ["unshare", "--mount", "sh", "-c", 'mount --bind -o ro "$0" "$0" && exec "$@"',
                str(site), *cmd]
    return cmd


def _dependency_dirs() -> list[str]:
    """The running environment's site-packages directories (a venv's, or the system's)."""
    paths = sysconfig.get_paths()
    return list(dict.fromkeys(p for p in (paths["purelib"], paths["platlib"])
                              if Path(p).is_dir()))


@pytest.fixture(scope="module")
def wheel_venv():
    base = Path(tempfile.mkdtemp(prefix="vtolftc-install-"))
    try:
        src, venv = base / "src", base / "venv"
        _tracked_copy(src)
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
        py = venv / "bin" / "python"
        site = Path(subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig."
                                    "get_paths()['purelib'])"], capture_output=True, text=True,
                                   check=True).stdout.strip())
        r = subprocess.run([str(py), "-m", "pip", "install", "--no-deps", "-q", str(src)],
                           capture_output=True, text=True, timeout=900)
        assert r.returncode == 0, r.stderr[-3000:]
        shutil.rmtree(src)  # nothing may still point into a source tree
        # after the install, so that pip never sees this checkout's own (editable) install
        (site / "zz_borrowed_dependencies.pth").write_text("".join(
            f"{d}\n" for d in _dependency_dirs()))
        if os.geteuid() != 0:  # no root to drop: make site-packages read-only instead
            for p in [site, *site.rglob("*")]:
                p.chmod(p.stat().st_mode & ~0o222)
        home = base / "home"
        home.mkdir()
        yield py, site, home
    finally:
        subprocess.run(["chmod", "-R", "u+w", str(base)], check=False)
        shutil.rmtree(base, ignore_errors=True)


def _run(venv: tuple[Path, Path, Path], args: list[str],
         timeout: float) -> subprocess.CompletedProcess:
    py, site, home = venv
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "NUMBA_CACHE"))}
    env.update(HOME=str(home), PATH=f"{py.parent}:{env.get('PATH', '')}", MPLBACKEND="Agg")
    return subprocess.run(_site_read_only(site, args), cwd=home, env=env, capture_output=True,
                          text=True, timeout=timeout)


def test_wheel_writes_only_the_vtolftc_package(wheel_venv):
    py, site, _home = wheel_venv
    tops = {p.name for p in site.iterdir() if not p.name.endswith((".dist-info", ".pth"))
            and p.name != "__pycache__"}
    ours = {t for t in tops if t in {"vtolftc", "airframe", "synthesis", "dashboard",
                                     "protocols", "gcs", "firmware_sim"}}
    assert ours == {"vtolftc"}
    r = _run(wheel_venv, [str(py), "-c",
                        "import vtolftc.firmware_sim.autopilot.autopilot as a, "
                        "vtolftc.synthesis.mu as m, vtolftc.protocols.mavlink as p, "
                        "vtolftc.dashboard.web as w; p.dialect(); "
                        "print(a.__file__, m.__file__, p.__file__, w.__file__); "
                        "open(p.__file__ + '.probe', 'w')"], 300)
    # the probe proves site-packages is read-only for the run; everything else worked before it
    assert r.returncode == 1 and ("Read-only" in r.stderr or "Permission" in r.stderr), r.stderr
    assert all(f.startswith(str(site)) for f in r.stdout.split()), r.stdout
    assert len(r.stdout.split()) == 4


def test_readme_first_command_from_outside_the_checkout(wheel_venv):
    py, _site, home = wheel_venv
    out = home / "compare"
    r = _run(wheel_venv, [str(py.parent / "vtolftc"), "compare", "--case", "1", "--out",
                        str(out)], 900)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    results = json.loads((out / "comparison.json").read_text())
    assert set(results) == {"gs-shif", "shif", "lqr"}
    assert not any(m["crashed"] for m in results.values())


def test_sitl_from_outside_the_checkout(wheel_venv):
    py, _site, home = wheel_venv
    out = home / "sitl"
    r = _run(wheel_venv, [str(py.parent / "vtolftc"), "sitl", "--case", "1", "--out", str(out)],
             900)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    metrics = json.loads((out / "autopilot" / "metrics.json").read_text())
    assert not metrics["crashed"] and metrics["transition_complete_s"] is not None
