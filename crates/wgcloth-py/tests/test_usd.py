"""USD files of runs (`wgcloth run --export usd`, `wgcloth.write_usd`), read
back with Pixar's own library and checked against the OBJ frames of the
same run."""

import numpy as np
import pytest
from pxr import Usd, UsdGeom

import wgcloth

STEPS, EVERY = 40, 20  # the body reaches the 16² cloth between steps 20 and 40


def small():
    return wgcloth.Scene(model="friction", cloth={"grid": [16, 16]})


def obj_objects(path):
    """An OBJ frame's objects: name → vertices (float32, as written)."""
    objects, name = {}, None
    for line in path.read_text().splitlines():
        if line.startswith("o "):
            name = line.split()[1]
            objects[name] = []
        elif line.startswith("v "):
            objects[name].append([float(c) for c in line.split()[1:]])
    return {k: np.array(v, dtype=np.float32) for k, v in objects.items()}


def points(stage, prim, time):
    return np.array(UsdGeom.Mesh(stage.GetPrimAtPath(prim)).GetPointsAttr().Get(time), dtype=np.float32)


def test_the_commands_usd_file_holds_its_obj_frames(cli, tmp_path):
    scene = small()
    (tmp_path / "scene.toml").write_text(scene.to_toml())
    out = tmp_path / "frames"
    cli("run", "--config", tmp_path / "scene.toml", "--backend", "cpu", "--steps", STEPS,
        "--every", EVERY, "--size", 64, "--out", out, "--export", "obj,usd")
    stage = Usd.Stage.Open(str(out / "animation.usda"))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == pytest.approx(1 / scene.config["solver"]["dt"])
    assert stage.GetFramesPerSecond() == stage.GetTimeCodesPerSecond()
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, STEPS)
    cloth = UsdGeom.Mesh(stage.GetPrimAtPath("/World/cloth"))
    assert cloth.GetPointsAttr().GetTimeSamples() == [0.0, 20.0, 40.0]
    assert list(cloth.GetFaceVertexCountsAttr().Get()) == [3] * len(scene.triangles)
    assert list(cloth.GetFaceVertexIndicesAttr().Get()) == scene.triangles.ravel().tolist()
    body = UsdGeom.Mesh(stage.GetPrimAtPath("/World/body"))
    assert body.GetPointsAttr().GetTimeSamples() == [0.0, 20.0, 40.0]
    for k, step in enumerate([0, 20, 40]):
        frame = obj_objects(out / f"frame_{k:04}.obj")
        np.testing.assert_array_equal(points(stage, "/World/cloth", step), frame["cloth"])
        np.testing.assert_array_equal(points(stage, "/World/body", step), frame["body"])
        extent = np.array(cloth.GetExtentAttr().Get(step))
        np.testing.assert_array_equal(extent, [frame["cloth"].min(0), frame["cloth"].max(0)])
    assert not np.array_equal(points(stage, "/World/cloth", 40), points(stage, "/World/cloth", 0))


def test_a_python_run_written_as_usd_reads_back_as_its_arrays(tmp_path):
    scene = small()
    sim = wgcloth.Simulator(scene, backend="cpu")
    frames, steps = [sim.positions[0]], [0]
    for _ in range(2):
        sim.step(EVERY)
        frames.append(sim.positions[0])
        steps.append(sim.steps)
    path = tmp_path / "run.usda"
    wgcloth.write_usd(path, scene, np.stack(frames), steps)
    stage = Usd.Stage.Open(str(path))
    for frame, step in zip(frames, steps):
        np.testing.assert_array_equal(points(stage, "/World/cloth", step), frame)
    assert points(stage, "/World/body", 0).shape[0] > 0
    assert not np.array_equal(points(stage, "/World/body", 0), points(stage, "/World/body", 40))
    with pytest.raises(ValueError, match="shape"):
        wgcloth.write_usd(tmp_path / "bad.usda", scene, np.stack(frames)[:, :10], steps)
    with pytest.raises(ValueError, match="each after the last"):
        wgcloth.write_usd(tmp_path / "bad.usda", scene, np.stack(frames), steps[::-1])
    assert not (tmp_path / "bad.usda").exists()
    before = path.read_bytes()
    with pytest.raises(wgcloth.WgclothError, match="already exists"):
        wgcloth.write_usd(path, scene, np.stack(frames), steps)
    assert path.read_bytes() == before
