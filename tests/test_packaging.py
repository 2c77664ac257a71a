"""pyproject.toml as current setuptools wants it: the licence an SPDX expression with its files, not the TOML
table setuptools deprecates (builds with it stop being supported on 2027-02-18)."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SPDX_SINCE = (77, 0)  # the first setuptools that reads `license` as an SPDX string and `license-files`


def test_the_license_is_an_spdx_expression_with_its_files_and_the_build_asks_a_setuptools_that_reads_them():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    project = meta["project"]
    assert project["license"] == "Apache-2.0"
    assert project["license-files"] and all(list(ROOT.glob(g)) for g in project["license-files"])
    assert "Apache License" in (ROOT / "LICENSE").read_text()[:200]
    wanted = [r for r in meta["build-system"]["requires"] if re.match(r"setuptools\b", r)]
    low = re.search(r">=\s*(\d+)(?:\.(\d+))?", wanted[0])
    assert (int(low[1]), int(low[2] or 0)) >= SPDX_SINCE
