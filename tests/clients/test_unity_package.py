"""sdk_clients/unity is a Unity package (UPM) that Unity can import as it is.

No Unity editor runs here, so the package is checked against the rules Unity applies on
import: the manifest's fields and their forms, a ``.meta`` with a unique GUID beside every
file and folder (folders ending in ``~`` are hidden from Unity and have none, their
contents do: a sample is copied into the project with them), no ``.meta`` without its
asset, assembly references that name assemblies of the package, and scene and prefab
files whose scripts are the package's own (by GUID) and whose internal references
resolve within the file.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import yaml

from tests.clients.live import ROOT

UNITY = ROOT / "sdk_clients" / "unity"
GUID = re.compile(r"^guid: ([0-9a-f]{32})$", re.MULTILINE)
PACKAGE_NAME = re.compile(r"^com\.[a-z0-9-]+(\.[a-z0-9-]+)+$")
SEMVER = re.compile(r"^\d+\.\d+\.\d+(-[0-9A-Za-z.-]+)?$")
UNITY_VERSION = re.compile(r"^20\d\d\.\d$")
SCRIPT_REF = re.compile(r"m_Script: \{fileID: 11500000, guid: ([0-9a-f]{32}), type: 3\}")
LOCAL_REF = re.compile(r"\{fileID: (\d+)\}")
OBJECT_HEADER = re.compile(r"^--- !u!(\d+) &(\d+)$", re.MULTILINE)
BUILTIN_GUIDS = {"0000000000000000e000000000000000", "0000000000000000f000000000000000"}


def assets() -> list[Path]:
    """Everything Unity imports from the package (and sample contents), .meta excluded."""
    return [
        path
        for path in sorted(UNITY.rglob("*"))
        if path.suffix != ".meta" and not path.name.endswith("~")
    ]


def guid_of(meta: Path) -> str:
    match = GUID.search(meta.read_text(encoding="utf-8"))
    assert match, f"{meta.relative_to(UNITY)} has no 32-hex guid"
    return match.group(1)


def test_manifest_has_what_the_package_manager_needs() -> None:
    manifest = json.loads((UNITY / "package.json").read_text(encoding="utf-8"))
    assert PACKAGE_NAME.match(manifest["name"]), manifest["name"]
    assert SEMVER.match(manifest["version"]), manifest["version"]
    assert UNITY_VERSION.match(manifest["unity"]), manifest["unity"]
    assert manifest["displayName"] and manifest["description"]
    for name, version in manifest["dependencies"].items():
        assert PACKAGE_NAME.match(name) and SEMVER.match(version), (name, version)
    assert "com.unity.modules.unitywebrequest" in manifest["dependencies"]
    assert "com.unity.modules.physics" in manifest["dependencies"]
    for sample in manifest["samples"]:
        folder = UNITY / sample["path"]
        assert sample["path"].startswith("Samples~/") and folder.is_dir(), sample["path"]
        assert sample["displayName"] and sample["description"]


def test_samples_hold_a_scene_and_prefabs() -> None:
    manifest = json.loads((UNITY / "package.json").read_text(encoding="utf-8"))
    folders = [UNITY / sample["path"] for sample in manifest["samples"]]
    assert any(list(folder.glob("*.unity")) for folder in folders)
    assert any(list(folder.glob("*.prefab")) for folder in folders)
    assert not (UNITY / "Samples").exists(), "Samples~, so Unity imports samples on request"


def test_every_asset_has_a_meta_with_a_unique_guid() -> None:
    found = assets()
    assert len(found) > 10
    missing = [
        str(p.relative_to(UNITY)) for p in found if not p.with_name(p.name + ".meta").is_file()
    ]
    assert missing == []
    guids = [guid_of(p.with_name(p.name + ".meta")) for p in found]
    assert len(set(guids)) == len(guids), "GUIDs are unique"
    orphans = [
        str(meta.relative_to(UNITY))
        for meta in UNITY.rglob("*.meta")
        if not meta.with_name(meta.name.removesuffix(".meta")).exists()
    ]
    assert orphans == []


def test_folder_metas_say_so_and_file_metas_do_not() -> None:
    for path in assets():
        text = path.with_name(path.name + ".meta").read_text(encoding="utf-8")
        assert text.startswith("fileFormatVersion: 2\n"), path
        assert ("folderAsset: yes" in text) is path.is_dir(), path


def test_assembly_references_name_package_assemblies() -> None:
    definitions = {
        json.loads(p.read_text(encoding="utf-8"))["name"]: json.loads(p.read_text(encoding="utf-8"))
        for p in UNITY.rglob("*.asmdef")
    }
    assert {"PhantomTouch.Core", "PhantomTouch", "PhantomTouch.Samples"} <= set(definitions)
    for name, definition in definitions.items():
        assert set(definition.get("references", [])) <= set(definitions), name
    assert definitions["PhantomTouch.Core"]["noEngineReferences"] is True


@pytest.mark.parametrize("suffix", [".unity", ".prefab"])
def test_scenes_and_prefabs_refer_to_the_package_scripts(suffix: str) -> None:
    scripts = {
        guid_of(meta): meta.name.removesuffix(".cs.meta") for meta in UNITY.rglob("*.cs.meta")
    }
    files = list(UNITY.rglob(f"*{suffix}"))
    assert files
    for path in files:
        text = path.read_text(encoding="utf-8")
        assert text.startswith("%YAML 1.1\n%TAG !u! tag:unity3d.com,2011:\n")
        used = SCRIPT_REF.findall(text)
        assert set(used) <= set(scripts), f"{path.name}: unknown script GUID"
        ids = {int(fid) for _, fid in OBJECT_HEADER.findall(text)}
        refs = {int(fid) for fid in LOCAL_REF.findall(text)} - {0}
        assert refs <= ids, f"{path.name}: references to objects not in the file: {refs - ids}"
        foreign = set(re.findall(r"guid: ([0-9a-f]{32})", text)) - set(scripts) - BUILTIN_GUIDS
        assert foreign == set(), f"{path.name} refers to assets outside the package"
        documents = text.split("\n--- ")[1:]
        for document in documents:
            body = yaml.safe_load(document.split("\n", 1)[1])
            assert isinstance(body, dict) and len(body) == 1, document[:80]


def test_scene_wires_the_zone_to_the_manager() -> None:
    scene = next(UNITY.rglob("*.unity")).read_text(encoding="utf-8")
    forearm = next(UNITY.rglob("Forearm.prefab")).read_text(encoding="utf-8")
    manager_guid = guid_of(next(UNITY.rglob("PhantomTouchManager.cs.meta")))
    zone_guid = guid_of(next(UNITY.rglob("ForearmTouchZone.cs.meta")))
    objects = dict(
        (int(fid), body)
        for fid, body in re.findall(r"^--- !u!\d+ &(\d+)\n(.*?)(?=^--- |\Z)", scene, re.M | re.S)
    )
    manager = [fid for fid, body in objects.items() if manager_guid in body]
    zone = next(body for body in objects.values() if zone_guid in body)
    assert len(manager) == 1
    assert f"manager: {{fileID: {manager[0]}}}" in zone
    assert "m_IsTrigger: 1" in scene, "the forearm's collider is a trigger"
    assert zone_guid in forearm and "m_IsTrigger: 1" in forearm
    assert "m_IsKinematic: 1" in scene, "the fingertip has a kinematic Rigidbody"
