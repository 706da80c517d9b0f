"""deploy/compose runs whichever Docker Compose the host has, and says so when it has none."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "deploy" / "compose"


def test_without_any_compose_it_fails_with_one_clear_line(tmp_path: Path) -> None:
    # a PATH holding only the shell tools the script uses, no docker at all
    for tool in ("sh", "dirname"):
        found = shutil.which(tool)
        assert found is not None, f"no {tool} on this machine"
        (tmp_path / tool).symlink_to(found)
    result = subprocess.run([str(SCRIPT), "version"], capture_output=True, check=False, text=True, env={"PATH": str(tmp_path)})
    assert result.returncode == 127
    assert result.stderr.strip().splitlines() == [
        "deploy/compose: neither 'docker compose' nor 'docker-compose' is installed "
        "(Docker Compose v1.29+ or the v2 plugin)"]


@pytest.mark.skipif(not shutil.which("docker"), reason="no docker here")
def test_it_runs_the_installed_compose() -> None:
    result = subprocess.run([str(SCRIPT), "version"], capture_output=True, check=False, text=True)
    if result.returncode == 127:
        pytest.skip("docker without compose here")
    assert result.returncode == 0, result.stderr
    assert "version" in result.stdout.lower()
