"""docs/results.md is what experiments/results_doc.py makes of experiments/results/*.json."""

from __future__ import annotations

import re

import results_doc


def test_docs_results_md_is_regenerated_from_the_json_files():
    committed = results_doc.DOCUMENT.read_text(encoding="utf-8")
    assert committed == results_doc.document(), (
        "docs/results.md differs from experiments/results/*.json: run python experiments/results_doc.py")


def test_every_result_file_the_document_names_exists():
    named = set(re.findall(r"experiments/results/[\w.]+", results_doc.document()))
    missing = sorted(name for name in named if not (results_doc.REPOSITORY / name).is_file())
    assert named and not missing, f"docs/results.md names missing files: {missing}"


def test_every_command_the_document_shows_names_an_experiment_script():
    scripts = set(re.findall(r"python (experiments/\w+\.py)", results_doc.document()))
    missing = sorted(script for script in scripts if not (results_doc.REPOSITORY / script).is_file())
    assert scripts and not missing, f"docs/results.md shows commands of missing scripts: {missing}"


def test_check_mode_passes_on_the_committed_document():
    assert results_doc.main(["--check"]) == 0
