"""Scenes from dicts, RON text and files; renders to NumPy arrays; errors as exceptions."""

import _thread
import copy
import errno
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import tress


def test_render_is_a_finite_float32_image_of_the_film(scene):
    image = scene.render()
    assert isinstance(image, np.ndarray)
    assert image.shape == (16, 16, 3)
    assert image.dtype == np.float32
    assert np.isfinite(image).all()
    assert (image >= 0).all()
    # Sky behind the ball and lit hair in front: nothing is black on average.
    assert image.mean() > 0.01


def test_the_same_seed_gives_the_same_image_and_another_seed_another(scene):
    a = scene.render(seed=7)
    b = scene.render(seed=7)
    c = scene.render(seed=8)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    # The scene's own seed is the default.
    np.testing.assert_array_equal(scene.render(), scene.render(seed=scene.seed))


def test_threads_and_crop_do_not_change_the_pixels(scene):
    full = scene.render(threads=2)
    np.testing.assert_array_equal(full, scene.render(threads=1))
    window = scene.render(crop=(3, 5, 11, 14))
    assert window.shape == (9, 8, 3)
    np.testing.assert_array_equal(window, full[5:14, 3:11])


def test_spp_and_size_overrides(scene):
    image = scene.render(spp=1, width=12, height=8)
    assert image.shape == (8, 12, 3)
    assert not np.array_equal(scene.render(spp=1), scene.render(spp=4))


def test_integrator_override_by_name_and_by_ron(scene):
    default = scene.render()
    # The scene names no integrator: `path` with its defaults is what it renders with.
    np.testing.assert_array_equal(default, scene.render(integrator="path"))
    assert scene.integrator.startswith("Path(")
    # One bounce drops the light scattered among the fibers: blond hair gets darker.
    single = scene.render(integrator="Path(max_depth: 1)", spp=8)
    multiple = scene.render(integrator="Path(max_depth: 100)", spp=8)
    assert single.mean() < 0.9 * multiple.mean()


# The integrators that learn from the film's own paths: they learn from a crop's pixels alone.
LEARNING = {"radiance-cache", "guided"}


def test_every_registered_integrator_renders_threads_and_crops_alike(scene):
    for name in tress.INTEGRATORS:
        full = scene.render(integrator=name, threads=2)
        assert np.isfinite(full).all() and full.mean() > 0, name
        np.testing.assert_array_equal(full, scene.render(integrator=name, threads=1), name)
        window = scene.render(integrator=name, crop=(3, 5, 11, 14), threads=2)
        np.testing.assert_array_equal(
            window, scene.render(integrator=name, crop=(3, 5, 11, 14), threads=1), name
        )
        if name not in LEARNING:
            np.testing.assert_array_equal(window, full[5:14, 3:11], name)


def test_a_learning_integrator_trains_on_the_crop_alone(scene):
    # Training the whole 4096² film, 2^24 pixels × 256 paths, would take days; the 4×4 window's
    # 16 pixels take a moment. The alarm turns a whole-film training into a failure, not a hang.
    def too_slow(signum, frame):
        raise TimeoutError("a 4x4 crop trained for more than 120 s")

    previous = signal.signal(signal.SIGALRM, too_slow)
    signal.alarm(120)
    try:
        for name in sorted(LEARNING):
            integrator = {"radiance-cache": "RadianceCache", "guided": "Guided"}[name]
            image = scene.render(
                integrator=f"{integrator}(training_spp: 256)",
                width=4096,
                height=4096,
                crop=(2046, 2046, 2050, 2050),
                spp=16,
            )
            assert image.shape == (4, 4, 3) and np.isfinite(image).all(), name
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def test_from_ron_and_to_ron_round_trip(scene):
    again = tress.Scene.from_ron(scene.to_ron())
    np.testing.assert_array_equal(again.render(), scene.render())
    assert (again.width, again.height, again.spp, again.seed) == (16, 16, 2, 1)


def test_a_table_cache_keeps_the_fur_table_and_changes_no_pixel(tmp_path, scene_dict):
    scene_dict["materials"]["blond"]["Hair"] = {
        "Fur": {"medulla_ratio": 0.5, "medulla_sigma_s": 3.0, "pigment": {"Melanin": {"eumelanin": 0.3}}}
    }
    cache = tmp_path / "tables"
    first = tress.Scene.from_dict(scene_dict, table_cache=cache)
    (stored,) = cache.iterdir()
    assert stored.name.startswith("fur-medulla-v")
    second = tress.Scene.from_dict(scene_dict, table_cache=str(cache))
    uncached = tress.Scene.from_dict(scene_dict)
    np.testing.assert_array_equal(second.render(), first.render())
    np.testing.assert_array_equal(uncached.render(), first.render())
    model = tress.HairModel("Fur(medulla_ratio: 0.5, medulla_sigma_s: 3.0)", table_cache=cache)
    assert len(model.lobes) == 6
    # A damaged file is a RuntimeWarning, and the table is built again and stored.
    stored.write_bytes(stored.read_bytes()[:100])
    with pytest.warns(RuntimeWarning, match="truncated"):
        again = tress.Scene.from_dict(scene_dict, table_cache=cache)
    np.testing.assert_array_equal(again.render(), first.render())
    assert stored.stat().st_size > 100


def test_a_scene_file_renders_as_its_dict(tmp_path, scene):
    path = tmp_path / "ball.ron"
    path.write_text(scene.to_ron())
    loaded = tress.load_scene(path)
    np.testing.assert_array_equal(loaded.render(), scene.render())
    assert str(path) in repr(loaded)
    assert "300 strands" in loaded.summary


def test_numpy_values_and_tuples_are_accepted_in_dicts(scene_dict, scene):
    scene_dict["camera"]["look_from"] = np.array([0.0, 0.0, 4.0])
    scene_dict["camera"]["fov"] = np.float32(35)
    scene_dict["film"]["width"] = np.int64(16)
    scene_dict["camera"]["look_at"] = (0, 0, 0)
    np.testing.assert_array_equal(tress.Scene.from_dict(scene_dict).render(), scene.render())


TRIANGLE_OBJ = "v -1 -1 -1\nv 1 -1 -1\nv 0 1 -1\nf 1 2 3\n"


def mesh_scene(scene_dict):
    scene_dict["materials"]["grey"] = {"Diffuse": {"albedo": [0.5, 0.5, 0.5]}}
    scene_dict["objects"] = [{"Mesh": {"file": "triangle.obj", "material": "grey"}}]
    return scene_dict


def test_relative_paths_resolve_against_base_dir(tmp_path, scene_dict, monkeypatch):
    (tmp_path / "triangle.obj").write_text(TRIANGLE_OBJ)
    d = mesh_scene(scene_dict)
    assert tress.Scene.from_dict(d, base_dir=tmp_path).render().mean() > 0
    # Without base_dir: the current directory.
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    with pytest.raises(FileNotFoundError, match="triangle.obj"):
        tress.Scene.from_dict(d)
    monkeypatch.chdir(tmp_path)
    tress.Scene.from_dict(d)
    ron = tress.Scene.from_dict(d).to_ron()
    monkeypatch.chdir(elsewhere)
    assert tress.Scene.from_ron(ron, base_dir=tmp_path).render().mean() > 0
    # A scene file's paths resolve against its own folder, wherever Python runs.
    (tmp_path / "mesh.ron").write_text(ron)
    assert tress.load_scene(tmp_path / "mesh.ron").render().mean() > 0


def test_missing_files_raise_oserror(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing.ron"):
        tress.load_scene(tmp_path / "nothing.ron")
    assert issubclass(FileNotFoundError, OSError)


def test_exceptions_follow_the_kind_of_error_not_its_text(tmp_path, scene, scene_dict):
    # A missing scene file: FileNotFoundError, with the operating system's errno.
    with pytest.raises(FileNotFoundError, match="nothing.ron") as missing:
        tress.load_scene(tmp_path / "nothing.ron")
    assert missing.value.errno == errno.ENOENT
    # A folder where a file should be: the scene itself, or a hair file it reads.
    (tmp_path / "folder.ron").mkdir()
    with pytest.raises(IsADirectoryError, match="folder.ron"):
        tress.load_scene(tmp_path / "folder.ron")
    (tmp_path / "strands.hair").mkdir()
    hair = scene_dict["objects"][0]["Hair"]
    hair["source"] = {"File": "strands.hair"}
    with pytest.raises(IsADirectoryError, match=r"objects\[0\]: .*strands\.hair"):
        tress.Scene.from_dict(scene_dict, base_dir=tmp_path)
    # A missing environment map, which the image reader reports without an OS error.
    with_map = mesh_scene(copy.deepcopy(scene_dict))
    (tmp_path / "triangle.obj").write_text(TRIANGLE_OBJ)
    with_map["lights"] = [{"Environment": {"file": "nowhere.exr"}}]
    with pytest.raises(FileNotFoundError, match=r"lights\[0\]: .*nowhere\.exr"):
        tress.Scene.from_dict(with_map, base_dir=tmp_path)
    # Malformed RON: ValueError naming the file and the line.
    text = scene.to_ron().replace("fov:", "fov: @")
    line = 1 + next(i for i, l in enumerate(text.splitlines()) if "fov: @" in l)
    (tmp_path / "broken.ron").write_text(text)
    with pytest.raises(ValueError, match=rf"broken\.ron:{line}:\d+: "):
        tress.load_scene(tmp_path / "broken.ron")
    # Text that reads like an OS error is still a bad input (the type was once parsed from it).
    hair["source"] = {"Procedural": {"style": "Ball"}}
    hair["material"] = "lost (os error 2)"
    with pytest.raises(ValueError, match=r"unknown material 'lost \(os error 2\)'"):
        tress.Scene.from_dict(scene_dict)


def test_malformed_scene_files_name_file_line_and_column(tmp_path, scene):
    text = scene.to_ron().replace("fov:", "fvo:")
    line = 1 + next(i for i, l in enumerate(text.splitlines()) if "fvo:" in l)
    path = tmp_path / "typo.ron"
    path.write_text(text)
    with pytest.raises(ValueError, match=rf"typo\.ron:{line}:\d+: .*fvo"):
        tress.load_scene(path)
    with pytest.raises(ValueError, match=rf"^<ron>:{line}:\d+: .*fvo"):
        tress.Scene.from_ron(text)


def test_dict_errors_name_where_the_value_sits(scene_dict):
    scene_dict["objects"][0]["Hair"]["source"] = {"Procedurl": {}}
    with pytest.raises(ValueError, match=r"objects\[0\]\.Hair\.source: unknown variant `Procedurl`"):
        tress.Scene.from_dict(scene_dict)


def test_invalid_values_are_refused_with_the_cli_messages(scene_dict):
    scene_dict["objects"][0]["Hair"]["material"] = "auburn"
    with pytest.raises(ValueError, match=r"<dict>: objects\[0\]: .*auburn"):
        tress.Scene.from_dict(scene_dict)
    scene_dict["objects"][0]["Hair"]["material"] = "blond"
    scene_dict["materials"]["blond"]["Hair"]["Chiang"]["beta_m"] = 7.0
    with pytest.raises(ValueError, match="material 'blond': beta_m = 7"):
        tress.Scene.from_dict(scene_dict)


def test_values_json_cannot_hold_are_refused(scene_dict):
    scene_dict["camera"]["fov"] = float("nan")
    with pytest.raises(ValueError, match=r"camera\.fov: NaN is not a finite number"):
        tress.Scene.from_dict(scene_dict)
    scene_dict["camera"]["fov"] = object()
    with pytest.raises(TypeError, match=r"camera\.fov: a value of type object"):
        tress.Scene.from_dict(scene_dict)


def test_self_containing_and_very_deep_values_are_refused(scene_dict):
    # Both overflowed the stack and killed the interpreter.
    scene_dict["camera"]["look_from"] = scene_dict
    with pytest.raises(ValueError, match=r"camera\.look_from.*nested more than 64 levels"):
        tress.Scene.from_dict(scene_dict)
    deep = []
    for _ in range(100_000):
        deep = [deep]
    scene_dict["camera"]["look_from"] = deep
    with pytest.raises(ValueError, match="nested more than 64 levels"):
        tress.Scene.from_dict(scene_dict)
    # A tuple holding itself through a list: the bound is on depth, whatever the container.
    loop = [1.0]
    loop.append((loop,))
    scene_dict["film"] = {"width": loop}
    with pytest.raises(ValueError, match="nested more than 64 levels"):
        tress.Scene.from_dict(scene_dict)


def test_bad_render_settings_raise_valueerror(scene):
    with pytest.raises(ValueError, match="spp must be at least 1"):
        scene.render(spp=0)
    with pytest.raises(ValueError, match="crop window"):
        scene.render(crop=(0, 0, 17, 16))
    # Thousands of threads on a tiny image crawled.
    with pytest.raises(ValueError, match="100000 worker threads: at most"):
        scene.render(threads=100000)
    with pytest.raises(ValueError, match="unknown integrator 'bogus'.*path, dual-uniform"):
        scene.render(integrator="bogus")


def test_ctrl_c_stops_a_render(scene):
    # A process started in the background (`cmd &` in a script) inherits SIGINT ignored, and
    # Python then installs no handler, so `interrupt_main` would do nothing: install Python's.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    # About a minute of work at 64x64 and 4096 spp: far longer than a stop takes.
    timer = threading.Timer(0.5, _thread.interrupt_main)
    start = time.monotonic()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            scene.render(spp=4096, width=64, height=64)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    assert time.monotonic() - start < 10
    # The scene still renders afterwards.
    assert scene.render().shape == (16, 16, 3)


def test_the_memory_limit_holds_for_the_whole_scene(scene_dict, monkeypatch):
    # 100 000 objects each far below the limit aborted the interpreter: together they are
    # refused at the one that crosses it, by name and with the totals.
    monkeypatch.setenv("TRESS_MEMORY_LIMIT_GIB", "0.1")
    hair = scene_dict["objects"][0]
    hair["Hair"]["source"]["Procedural"]["strands"] = 1
    scene_dict["objects"] = [hair] * 100_000
    with pytest.raises(
        ValueError,
        match=r"objects\[\d+\]: .*GiB of the objects before it, over the 0\.1 GiB limit "
        r"for the whole scene",
    ):
        tress.Scene.from_dict(scene_dict)


USD_GROOM = """#usda 1.0
def BasisCurves "Hair"
{
    uniform token type = "linear"
    int[] curveVertexCounts = [3]
    point3f[] points = [(0, 0, 0), (0, 1, 0), (0, 2, 0)]
    float[] widths = [0.1] (interpolation = "constant")
}
"""


def test_hostile_usd_grooms_raise_valueerror_naming_them(tmp_path, scene_dict):
    # Each raised PanicException, killed the interpreter or read uninitialised memory.
    (tmp_path / "other.usda").write_text('#usda 1.0\ndef "X" {}\n')
    usdc = bytearray(
        (Path(__file__).parents[2] / "groom/tests/data/usd_linear.usdc").read_bytes()
    )
    deep = "#usda 1.0\n" + 'def Xform "a" {\n' * 6000 + "}\n" * 6000
    cases = [
        ("short.usda", USD_GROOM.replace("(0, 2, 0)]", "(0, 2)]"), r"line 6, column \d+: .*tuple has 2"),
        ("empty.usda", USD_GROOM.replace("(0, 1, 0),", "(),"), "tuple has 0 elements"),
        ("deep.usda", deep, "nested more than 256 deep"),
        (
            "ref.usda",
            USD_GROOM.replace('"Hair"', '"Hair" (references = @other.usda@</Nope>)', 1),
            "Nope",
        ),
        ("sub.usda", USD_GROOM.replace("#usda 1.0", "#usda 1.0\n(subLayers = [@gone.usda@])"), "gone.usda"),
        # A reference path running on over lines: its composition never ended.
        (
            "runon.usda",
            USD_GROOM.replace('"Hair"', '"Hair" (references = </P\n)\n}\ndef "B" (references = </P>)', 1),
            r"line 2, column \d+: .*not a valid path",
        ),
    ]
    for i in range(0, len(usdc), 101):
        bytes_ = bytearray(usdc)
        bytes_[i] ^= 0xFF
        cases.append((f"flip{i}.usdc", bytes(bytes_), None))
    for name, content, expect in cases:
        path = tmp_path / name
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content)
        scene_dict["objects"][0]["Hair"]["source"] = {"File": str(path)}
        if expect is None:
            # A changed byte may leave a valid groom; an error names the file, never a panic.
            try:
                tress.Scene.from_dict(scene_dict)
            except ValueError as e:
                assert name in str(e) and "library failed" not in str(e), str(e)
            continue
        with pytest.raises(ValueError, match=expect) as e:
            tress.Scene.from_dict(scene_dict)
        assert name in str(e.value) and len(str(e.value)) < 2000
