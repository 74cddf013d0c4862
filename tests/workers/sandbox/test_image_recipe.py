"""The sandbox image carries what the evaluation runs (GNU ``patch``, the harness's last way to apply a
diff) and the recipe it was built from; an image of the tag built from another recipe is rebuilt
(issue 36 item 3: an image without ``patch`` kept being used where the tag existed)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from workers.sandbox import image
from workers.sandbox.image import DEFAULT_IMAGE, DEFAULT_PACKAGES, RECIPE_LABEL, build_image, recipe_hash


def test_the_recipe_holds_patch_and_its_hash_follows_what_the_image_is_made_of() -> None:
    assert "patch" in DEFAULT_PACKAGES
    assert recipe_hash() == recipe_hash(packages=tuple(reversed(DEFAULT_PACKAGES)))  # the order is not the recipe
    without_patch = tuple(p for p in DEFAULT_PACKAGES if p != "patch")
    assert recipe_hash(packages=without_patch) != recipe_hash()
    assert recipe_hash(suite="trixie") != recipe_hash()


@pytest.fixture
def builds(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> dict[str, object]:
    """``build_image`` with the daemon and debootstrap replaced: what it imported, under which recipe."""
    state: dict[str, object] = {"recipe": None, "imports": []}
    monkeypatch.setattr(image, "_LOCK", tmp_path / "lock")
    monkeypatch.setattr(image, "image_recipe", lambda tag: state["recipe"])
    monkeypatch.setattr(image, "image_size", lambda tag: 7)
    monkeypatch.setattr(image, "_debootstrap", lambda root, suite, mirror, packages, log: root.mkdir())
    monkeypatch.setattr(image, "_trim", lambda root: None)

    def fake_import(root: Path, tag: str, recipe: str) -> None:
        imports = state["imports"]
        assert isinstance(imports, list)
        imports.append((tag, recipe))
        state["recipe"] = recipe

    monkeypatch.setattr(image, "_import", fake_import)
    return state


@pytest.mark.parametrize(("present", "built"), [(None, True), ("", True), ("0123456789abcdef", True), ("current", False)])
def test_an_image_built_from_another_recipe_is_rebuilt(builds: dict[str, object], present: str | None, built: bool) -> None:
    """Missing (None), built before the label (""), or from another recipe: built; the same recipe: kept."""
    builds["recipe"] = recipe_hash() if present == "current" else present
    res = build_image("t/sandbox:x")
    assert (res.tag, res.built, res.size_bytes) == ("t/sandbox:x", built, 7)
    assert builds["imports"] == ([("t/sandbox:x", recipe_hash())] if built else [])
    again = build_image("t/sandbox:x")  # then it is current: nothing more is built
    assert again.built is False
    assert builds["imports"] == ([("t/sandbox:x", recipe_hash())] if built else [])


@pytest.mark.docker
def test_the_built_image_has_patch_and_is_labelled_with_its_recipe(docker_ready: str) -> None:
    assert docker_ready == DEFAULT_IMAGE
    label = subprocess.run(
        ["docker", "image", "inspect", "--format", f'{{{{index .Config.Labels "{RECIPE_LABEL}"}}}}', DEFAULT_IMAGE],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    assert label == recipe_hash()
    out = subprocess.run(
        [
            "docker",
            "run",
            "--rm",
            "--network",
            "none",
            DEFAULT_IMAGE,
            "sh",
            "-c",
            "patch --version | head -1; for p in git python pytest; do command -v $p; done",
        ],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert out.splitlines() == ["GNU patch 2.7.6", "/usr/bin/git", "/usr/bin/python", "/usr/bin/pytest"]
