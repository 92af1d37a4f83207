"""The pictures of a run (sintercond.output.plots): written, non-empty, decodable, and showing the data they are given."""

import copy

import numpy as np
import pytest
from matplotlib import colormaps
from matplotlib.image import imread
from test_scene_run import SMALL

from sintercond.output import plots
from sintercond import run as runner
from sintercond.scene import validate_scene


def _image(path):
    assert path.exists() and path.stat().st_size > 1000
    image = imread(path)[..., :3]  # PNG: floats in [0, 1], RGBA
    assert image.ndim == 3 and min(image.shape[:2]) > 200
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 10  # not blank: several colours
    return image


def _hot_pixel_columns(image, panel_fraction=0.9):
    """Columns (as fractions of the width) of the pixels that have the colour map's hottest colour, left of the colour bar."""
    hot = np.asarray(colormaps["inferno"](1.0)[:3])
    width = image.shape[1]
    near = np.all(np.abs(image[:, : int(panel_fraction * width)] - hot) < 0.03, axis=-1)
    return np.nonzero(near)[1] / width


@pytest.mark.slow
@pytest.mark.parametrize("hot", [0, 4])
def test_state_picture_colours_the_hot_particle(tmp_path, hot):
    """A row of five spheres along x, one at 900 K and the others at 300 K: the hottest colour is drawn where it is."""
    positions = np.stack([np.arange(5) * 2e-4, np.zeros(5), np.zeros(5)], axis=1)
    radii = np.full(5, 1e-4)
    temperature = np.where(np.arange(5) == hot, 900.0, 300.0)
    image = _image(plots.state_picture(tmp_path / "state.png", positions, radii, temperature, time=2.5e-3))
    columns = _hot_pixel_columns(image)
    assert columns.size > 100
    # two panels side by side, both with x across: the hot disc is at the left (hot = 0) or right end of each
    halves = [columns[columns < 0.45], columns[columns >= 0.45]]
    for half, (lo, hi) in zip(halves, [(0.0, 0.45), (0.45, 0.9)]):
        assert half.size > 50
        position = (half.mean() - lo) / (hi - lo)
        assert position < 0.4 if hot == 0 else position > 0.6


def test_state_picture_refuses_mismatched_arrays(tmp_path):
    with pytest.raises(ValueError, match="must agree"):
        plots.state_picture(tmp_path / "x.png", np.zeros((3, 3)), np.ones(2), np.ones(3))


def test_history_plot_of_synthetic_curves(tmp_path):
    t = np.linspace(0.0, 5e-3, 51)
    history = {"time": t, "T_max": 300 + 200 * np.sin(np.pi * t / 5e-3), "T_mean": 300 + 4e3 * t,
               "T_min": np.full_like(t, 300.0), "heat_in_W": np.full_like(t, 5.0)}
    _image(plots.history_plot(tmp_path / "history.png", history))
    with pytest.raises(ValueError, match="'time'"):
        plots.history_plot(tmp_path / "bad.png", {"T_max": t})
    with pytest.raises(ValueError, match=r"\['T_min'\] do not have the length"):
        plots.history_plot(tmp_path / "bad.png", {"time": t, "T_min": t[:-1]})


def test_units_and_time_labels():
    assert plots.length_unit(5e-4) == (1e6, "µm") and plots.length_unit(2e-3) == (1e3, "mm")
    assert plots.time_label(7.754e-3) == "7.75 ms" and plots.time_label(2.0) == "2 s"
    assert plots.time_label(3e-7) == "0.3 µs"


@pytest.mark.slow
def test_sintercond_run_writes_the_picture(tmp_path):
    scene = copy.deepcopy(SMALL)
    scene["run"].update(duration=2e-3, formats=["vtp"])
    _, summary = runner.run_scene(validate_scene(scene), tmp_path, progress=False)
    image = _image(tmp_path / plots.STATE_PICTURE)
    assert summary["T_max_K"] > 310.0  # the beam heated something: the hottest colour is on the picture
    assert _hot_pixel_columns(image).size > 20


@pytest.mark.slow
def test_every_figure_linked_from_the_docs_exists_and_decodes():
    """Every PNG embedded in benchmarks/RESULTS.md, docs/devlog/*.md and README.md is there, non-empty, and not blank."""
    import pathlib
    import re

    root = pathlib.Path(__file__).resolve().parents[1]
    links = [(root / "benchmarks" / m) for m in re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)",
                                                           (root / "benchmarks" / "RESULTS.md").read_text())]
    for page in sorted((root / "docs" / "devlog").glob("*.md")):  # links relative to the page
        links += [(page.parent / m) for m in re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", page.read_text())]
    assert root / "docs" / "devlog" / "../../benchmarks/figures/inverse_gradient_pipeadj.png" in links
    links += [(root / m) for m in re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", (root / "README.md").read_text())]
    assert root / "docs" / "default_scene.png" in links
    for path in links:
        _image(path)


def test_large_views_are_drawn_as_an_image_nearest_disc_in_front():
    """Issue 27: a million patches took minutes. Above RASTER_ABOVE discs a view is one image; each pixel shows
    the disc nearest the viewer that covers it, and pixels no disc covers stay empty (NaN)."""
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    ax = Figure().subplots()
    centres = np.array([[0.0, 0.0], [0.5, 0.0], [3.0, 3.0]])
    radii = np.array([1.0, 1.0, 0.01])  # the third is smaller than a pixel: it still shows, at its centre
    depth = np.array([0.0, 1.0, 0.0])  # the second lies in front of the first
    temperature = np.array([300.0, 900.0, 600.0])
    image = plots._raster_discs(ax, centres, radii, depth, temperature, Normalize(300, 900), "inferno",
                                limits=np.array([[-1.0, 3.0], [-1.0, 3.0]]), scale=1.0, pixels=400).get_array()
    pixel = lambda x, y: image[int((y + 1.0) / 0.01), int((x + 1.0) / 0.01)]  # noqa: E731
    assert pixel(0.25, 0.0) == 900.0  # where both cover it: the one in front
    assert pixel(-0.75, 0.0) == 300.0  # only the first reaches here
    assert pixel(3.0, 3.0) == 600.0
    assert np.ma.is_masked(pixel(2.0, -0.5))  # matplotlib masks the NaN of an empty pixel


def test_a_big_state_picture_is_written(tmp_path):
    rng = np.random.default_rng(0)
    n = plots.RASTER_ABOVE + 1000
    positions = rng.uniform(0, 1e-3, (n, 3))
    path = plots.state_picture(tmp_path / "big.png", positions, np.full(n, 1e-5), rng.uniform(300, 400, n), 1e-3)
    assert imread(path).shape[0] > 100
