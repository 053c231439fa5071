"""What a user who installs or cites the project reads: the licence, the citation file, the install extras."""

from __future__ import annotations

import tomllib
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


def test_licence_file_is_the_apache_2_text_that_pyproject_declares():
    assert _pyproject()["project"]["license"] == "Apache-2.0"
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert "Apache License" in text and "Version 2.0, January 2004" in text
    assert "TERMS AND CONDITIONS FOR USE, REPRODUCTION, AND DISTRIBUTION" in text
    assert "END OF TERMS AND CONDITIONS" in text and len(text.splitlines()) > 150


def test_citation_file_names_the_software_and_the_paper():
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    # the keys CFF 1.2.0 requires, and the ones this file promises
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software"
    assert cff["message"] and cff["title"] and cff["authors"]
    assert str(cff["version"]) == _pyproject()["project"]["version"]
    assert cff["license"] == _pyproject()["project"]["license"]
    (paper,) = cff["references"]
    assert paper["type"] == "article" and "footprint uncertainty" in paper["title"]
    assert [a["family-names"] for a in paper["authors"]] == ["Kusari", "Almutairi", "Gilbert", "LeBlanc"]
    assert any(i["value"] == "arXiv:2308.12846" for i in paper["identifiers"])


def test_demo_installs_the_core_only_and_test_the_dev_extras():
    """`make demo` must not wait on the development extras (dask, carla, atheris, ...): its stamp installs `-e .`."""
    mk = (ROOT / "Makefile").read_text(encoding="utf-8")
    demo_rule = mk.split("\n$(DEMO_STAMP):", 1)[1].split("\n\n", 1)[0]
    assert "install --progress-bar on -e ." in demo_rule and "[dev]" not in demo_rule
    assert "demo: $(DEMO_STAMP)" in mk
    installs = [line for line in mk.splitlines() if "pip install" in line and not line.lstrip().startswith("#")]
    assert len(installs) >= 3 and not any(" -q" in line for line in installs), "an install step is silent"
    extras = _pyproject()["project"]["optional-dependencies"]
    have = extras["dev"] + _pyproject()["project"]["dependencies"]
    for extra in ("geo", "service", "dask", "carla", "ros", "supervision"):
        for req in extras[extra]:
            name = req.split(">")[0].split("=")[0].split("[")[0]
            assert any(d.startswith(name) for d in have), f"dev misses {req} of the {extra} extra"
