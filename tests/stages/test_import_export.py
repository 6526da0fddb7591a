"""dcslam import / export as library calls: a layer exported to KITTI devkit PNGs and imported back is the same layer
within the PNGs' 1/256 m, in both layouts and with a crop put back in place; every malformed folder is refused in one
line naming the file, with nothing written."""
import json

import numpy as np
import pytest
from PIL import Image

from dcslam.errors import DcslamError
from dcslam.io.drive import DriveFile, load_depth, read_layer
from dcslam.stages import export_devkit, import_devkit
from dcslam.stages.export_devkit import ExportConfig
from dcslam.stages.import_devkit import ImportConfig
from dcslam.workspace import find_layer

DRIVES = ["drive_a", "drive_d"]


def drive_depth(ws, drive, kind="dense"):
    with DriveFile(ws.drives / f"{drive}.h5") as opened:
        return load_depth(opened, kind), opened.frame_ids


def as_devkit(depth):
    """What a devkit PNG keeps of a layer: 1/256 m steps, depths below 0.1 m as holes."""
    return np.where(depth >= 0.1, np.rint(depth * 256) / 256, 0)


def test_export_writes_the_benchmark_layout_the_devkit_reads(ws):
    out = ws.root / "devkit"
    result = export_devkit.run(ws, ExportConfig(depth="dense", out_dir=out, drive=DRIVES))
    assert result.list_file is None and len(result.files) == 8
    for drive in DRIVES:
        depth, frame_ids = drive_depth(ws, drive)
        folder = out / drive / "proj_depth" / "groundtruth" / "image_02"
        assert sorted(p.name for p in folder.iterdir()) == [f"{int(f):010d}.png" for f in frame_ids]
        for i, frame in enumerate(frame_ids):
            png = np.array(Image.open(folder / f"{int(frame):010d}.png"))
            assert png.dtype == np.uint16 and png.shape == depth.shape[1:]
            np.testing.assert_array_equal(png == 0, as_devkit(depth[i]) == 0)
            np.testing.assert_allclose(png / 256.0, depth[i] * (png > 0), atol=0.5 / 256)
    assert not list(out.rglob(".*"))  # no temporary left


@pytest.mark.parametrize("kind", ["sparse", "dense", "filtered"])
def test_round_trip_through_the_drive_layout(ws, kind):
    if kind == "filtered":
        from dcslam.stages.filter import FilterConfig, run as run_filter

        run_filter(ws, FilterConfig(filters=["range:min=1,max=30"], depth="dense", name="near", drive=DRIVES))
        kind = "filtered/near"
    out = ws.root / "devkit"
    export_devkit.run(ws, ExportConfig(depth=kind, out_dir=out, drive=DRIVES))
    result = import_devkit.run(ws, ImportConfig(src=out, name="back", drive=DRIVES))
    assert result.frames == 8 and result.out_dir == ws.predictions / "back"
    layer = find_layer(ws, "back")
    for drive in DRIVES:
        original = load_depth(DriveFile(ws.drives / f"{drive}.h5"), find_layer(ws, kind).source(drive))
        back = read_layer(layer.source(drive))
        np.testing.assert_allclose(back.depth, as_devkit(original), atol=0.5 / 256 + 1e-6)
        np.testing.assert_array_equal(back.frame_ids, drive_depth(ws, drive)[1])
        assert back.config["imported"]["source"] == str(out.resolve())
        assert back.config["imported"]["layout"] == "drive" and back.config["input"] == "sparse"
        assert back.config["imported"]["kind"] == {"sparse": "velodyne_raw", "dense": "groundtruth"}.get(kind,
                                                                                                          "prediction")
    config = json.loads((ws.predictions / "back" / "config.json").read_text())
    assert config["stage"] == "import" and config["settings"]["drives"] == DRIVES


def test_round_trip_through_the_index_layout_with_a_crop(ws):
    out = ws.root / "indexed"
    result = export_devkit.run(ws, ExportConfig(depth="dense", out_dir=out, layout="index", drive=DRIVES))
    assert result.list_file == out / "list.txt" and len(result.files) == 8
    assert sorted(p.name for p in out.glob("*.png")) == [f"{i:010d}.png" for i in range(8)]
    for png in out.glob("*.png"):  # the method cropped 8 rows off the top and 4 columns off the left
        Image.fromarray(np.array(Image.open(png))[8:, 4:]).save(png)
    import_devkit.run(ws, ImportConfig(src=out, name="cropped", layout="index", list_file=out / "list.txt",
                                       crop="8,4"))
    for drive in DRIVES:
        dense, _ = drive_depth(ws, drive)
        back = read_layer(ws.predictions / "cropped" / f"{drive}.h5")
        assert not back.depth[:, :8].any() and not back.depth[:, :, :4].any()
        np.testing.assert_allclose(back.depth[:, 8:, 4:], as_devkit(dense)[:, 8:, 4:], atol=0.5 / 256 + 1e-6)
        assert back.config["imported"]["crop"] == [8, 4]


def test_the_list_gives_the_order(ws):
    """Index files follow the list, not the drives' order: a list that starts with the last frame."""
    out = ws.root / "indexed"
    export_devkit.run(ws, ExportConfig(depth="dense", out_dir=out, layout="index", drive=["drive_d"]))
    lines = (out / "list.txt").read_text().splitlines()
    (out / "list.txt").write_text("\n".join([lines[-1], *lines[:-1]]) + "\n")
    pngs = sorted(out.glob("*.png"))
    data = [p.read_bytes() for p in pngs]
    for png, payload in zip(pngs, [data[-1], *data[:-1]]):
        png.write_bytes(payload)
    import_devkit.run(ws, ImportConfig(src=out, name="reordered", layout="index", list_file=out / "list.txt"))
    dense, _ = drive_depth(ws, "drive_d")
    np.testing.assert_allclose(read_layer(ws.predictions / "reordered" / "drive_d.h5").depth, as_devkit(dense),
                               atol=0.5 / 256 + 1e-6)


def frame_png(out, drive, frame, kind="groundtruth"):
    return out / drive / "proj_depth" / kind / "image_02" / f"{frame:010d}.png"


def _missing(out):
    frame_png(out, "drive_d", 2).unlink()
    return frame_png(out, "drive_d", 2), "not found"


def _extra(out):
    path = frame_png(out, "drive_d", 9)
    path.write_bytes(frame_png(out, "drive_d", 0).read_bytes())
    return path, "not a frame of drive drive_d"


def _wrong_size(out):
    path = frame_png(out, "drive_a", 1)
    Image.fromarray(np.array(Image.open(path))[2:]).save(path)
    return path, "30 × 64 pixels"


def _eight_bit(out):
    path = frame_png(out, "drive_d", 3)
    Image.fromarray(np.full((32, 64), 9, np.uint8)).save(path)
    return path, "16-bit"


def _out_of_range(out):
    path = frame_png(out, "drive_d", 0)
    png = np.array(Image.open(path))
    png[5, 5] = 65000
    Image.fromarray(png).save(path)
    return path, "outside 0.1-120 m"


def _other_drive(out):
    (out / "drive_b").mkdir()
    return out / "drive_b", "a drive not imported"


def _two_kinds(out):
    (out / "drive_a" / "proj_depth" / "velodyne_raw").mkdir()
    return out / "drive_a" / "proj_depth", "pass --kind"


@pytest.mark.parametrize("spoil", [_missing, _extra, _wrong_size, _eight_bit, _out_of_range, _other_drive, _two_kinds],
                         ids=lambda f: f.__name__.strip("_"))
def test_a_bad_folder_is_refused_naming_the_file_and_writes_nothing(ws, spoil):
    out = ws.root / "devkit"
    export_devkit.run(ws, ExportConfig(depth="dense", out_dir=out, drive=DRIVES))
    path, message = spoil(out)
    with pytest.raises(DcslamError, match=message) as error:
        import_devkit.run(ws, ImportConfig(src=out, name="bad", drive=DRIVES))
    assert str(path) in str(error.value) and "\n" not in str(error.value)
    assert not (ws.predictions / "bad").exists() and not ws.predictions.exists()


@pytest.mark.parametrize("edit, message", [
    (lambda lines: lines[:-1], "lists 3 of the 4 frames of drive_d"),
    (lambda lines: [*lines, "drive_d 0000000077"], "frame 77 of drive_d is not in its drive file"),
    (lambda lines: [*lines, *(f"drive_a {i}" for i in range(4))], "0000000004.png not found: 4 of the list's 8"),
])
def test_a_list_that_does_not_cover_its_drives_is_refused(ws, edit, message):
    out = ws.root / "indexed"
    export_devkit.run(ws, ExportConfig(depth="dense", out_dir=out, layout="index", drive=["drive_d"]))
    lines = (out / "list.txt").read_text().splitlines()
    (out / "list.txt").write_text("\n".join(edit(lines)) + "\n")
    with pytest.raises(DcslamError, match=message):
        import_devkit.run(ws, ImportConfig(src=out, name="bad", layout="index", list_file=out / "list.txt"))
    assert not (ws.predictions / "bad").exists()


def test_a_png_beyond_the_list_is_refused(ws):
    out = ws.root / "indexed"
    export_devkit.run(ws, ExportConfig(depth="dense", out_dir=out, layout="index", drive=["drive_d"]))
    (out / "0000000004.png").write_bytes((out / "0000000000.png").read_bytes())
    with pytest.raises(DcslamError, match="0000000004.png: beyond the 4 frames"):
        import_devkit.run(ws, ImportConfig(src=out, name="bad", layout="index", list_file=out / "list.txt"))


def test_nothing_is_overwritten_without_force(ws):
    out = ws.root / "devkit"
    export_devkit.run(ws, ExportConfig(depth="dense", out_dir=out, drive=["drive_d"]))
    with pytest.raises(DcslamError, match="not empty; pass --force"):
        export_devkit.run(ws, ExportConfig(depth="sparse", out_dir=out, drive=["drive_d"]))
    export_devkit.run(ws, ExportConfig(depth="dense", out_dir=out, drive=["drive_d"]), force=True)
    import_devkit.run(ws, ImportConfig(src=out, name="once", drive=["drive_d"]))
    before = (ws.predictions / "once" / "drive_d.h5").stat().st_mtime_ns
    with pytest.raises(DcslamError, match="exists; pass --force"):
        import_devkit.run(ws, ImportConfig(src=out, name="once", drive=["drive_d"]))
    assert (ws.predictions / "once" / "drive_d.h5").stat().st_mtime_ns == before
    import_devkit.run(ws, ImportConfig(src=out, name="once", drive=["drive_d"]), force=True)


def test_a_refused_export_leaves_no_file_or_folder(ws):
    """drive_d's layer file is drive_a's: refused after drive_a's PNGs were staged, which go again with their
    folders."""
    import shutil

    from dcslam.stages.filter import FilterConfig, run as run_filter

    run_filter(ws, FilterConfig(filters=["range"], depth="dense", name="swapped", drive=DRIVES))
    shutil.copy(ws.filtered / "swapped" / "drive_a.h5", ws.filtered / "swapped" / "drive_d.h5")
    out = ws.root / "devkit"
    with pytest.raises(DcslamError, match="a layer of drive 'drive_a', not of 'drive_d'"):
        export_devkit.run(ws, ExportConfig(depth="filtered/swapped", out_dir=out, drive=DRIVES))
    assert not out.exists()
    out.mkdir()
    with pytest.raises(DcslamError, match="not of 'drive_d'"):
        export_devkit.run(ws, ExportConfig(depth="filtered/swapped", out_dir=out, layout="index", drive=DRIVES))
    assert list(out.iterdir()) == []
    with pytest.raises(DcslamError, match="drive_b.h5 not found; run `dcslam filter` first"):
        export_devkit.run(ws, ExportConfig(depth="filtered/swapped", out_dir=out, drive=["drive_b"]))


@pytest.mark.parametrize("options, message", [
    ({}, "give --src"),
    ({"src": "x", "layout": "index"}, "needs --list"),
    ({"src": "x", "layout": "index", "list_file": "l", "drive": ["d"]}, "leave out --drive"),
    ({"src": "x", "list_file": "l"}, "--list is for --layout index"),
    ({"src": "x", "crop": "100"}, "ROWS,COLUMNS"),
    ({"src": "x", "name": "../up"}, "not a plain name"),
])
def test_import_options_are_checked(options, message):
    with pytest.raises(DcslamError, match=message):
        ImportConfig(**options)
