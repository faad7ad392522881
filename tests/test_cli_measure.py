"""The command line: --help everywhere, synth accuracy, measure with a bad image."""

import hashlib

import pandas as pd
import pytest

from vision_torsion.cli import COMMAND_MODULES, build_parser, main


def _tree_digest(folder):
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        h.update(str(p.relative_to(folder)).encode())
        if p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()


def _subcommands():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return sorted(sub.choices)


def test_every_module_registers_a_command():
    assert len(_subcommands()) >= len(COMMAND_MODULES)


@pytest.mark.parametrize("command", _subcommands())
def test_help_on_every_subcommand(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    assert "usage: vision-torsion" in capsys.readouterr().out


@pytest.fixture(scope="module")
def accuracy_dir(tmp_path_factory, small_scene):
    """A small accuracy folder rendered by the API the synth command uses."""
    from vision_torsion.synthetic.folders import write_accuracy_folder

    return write_accuracy_folder(
        small_scene, tmp_path_factory.mktemp("acc") / "acc", angles_deg=[-30.0, 12.5, 45.0], seed=3
    )


def test_synth_accuracy_command(tmp_path, scene_file, capsys):
    out = tmp_path / "a"
    assert main(["synth", "accuracy", str(out), "--scene", str(scene_file("small_target")), "--angles", "5", "-q"]) == 0
    ref = pd.read_csv(out / "reference.csv")
    assert list(ref.columns) == ["image", "reference_angle_deg"]
    assert ref["reference_angle_deg"].tolist() == [0.0, 5.0]
    assert (out / "truth.csv").is_file() and (out / ref["image"][1]).is_file()


def test_measure_writes_angles_and_continues_past_a_bad_image(accuracy_dir, tmp_path, capsys):
    images = tmp_path / "images"
    images.mkdir()
    for p in accuracy_dir.glob("*.png"):
        (images / p.name).write_bytes(p.read_bytes())
    (images / "img_002.png").write_bytes(b"\x89PNG\r\n\x1a\n broken")  # corrupt one image
    before = _tree_digest(images)
    out = tmp_path / "out"
    # an accuracy folder holds independent rotations (-30°, 12.5°, 45°): not a sequence of small steps
    code = main(
        [
            "measure",
            str(images),
            "--reference",
            str(images / "reference.png"),
            "-o",
            str(out),
            "-q",
            "--order",
            "independent",
        ]
    )
    assert code == 1  # one image failed
    table = pd.read_csv(out / "angles.csv")
    truth = pd.read_csv(accuracy_dir / "reference.csv").set_index("image")["reference_angle_deg"]
    bad = table[table["image"] == "img_002.png"].iloc[0]
    assert bad["status"] == "failed" and "img_002.png: truncated PNG" in bad["message"]
    good = table[table["status"] == "ok"].set_index("image")
    assert len(good) == 3
    err = (good["angle_deg"] - truth[good.index]).abs()
    assert err.max() < 0.01  # small scene: std ~0.001°
    assert (good["angle_std_deg"] > 0).all()
    assert _tree_digest(images) == before  # the input folder is never modified
    assert (
        "failed: " in (out := capsys.readouterr().err)
        and "img_002.png: truncated PNG" in out
        and out.count("img_002.png") == 1
    )


def test_measure_unusable_reference_exits_2(tmp_path, capsys):
    (tmp_path / "a.png").write_bytes(b"junk")
    assert main(["measure", str(tmp_path), "--reference", str(tmp_path / "missing.png"), "-q"]) == 2
    assert "missing.png: no such file" in capsys.readouterr().err


def test_measure_empty_folder_exits_2(tmp_path, capsys):
    assert main(["measure", str(tmp_path), "--reference", "x.png", "-q"]) == 2
    assert "no image files" in capsys.readouterr().err
