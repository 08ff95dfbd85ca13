"""Image comparison, reading and writing on arrays."""

import numpy as np
import pytest

import pcbpt


@pytest.fixture(scope="module")
def image(cornell):
    return pcbpt.render(cornell, seed=5, threads=2)


def test_an_image_against_itself_has_no_error(image):
    assert pcbpt.compare(image, image) == 0
    assert pcbpt.compare(image, image, "mse") == 0
    assert pcbpt.compare(image, image, "mean_ratio") == 1
    assert pcbpt.compare(image, image, "flip") == 0


def test_a_different_image_has_an_error(image, cornell):
    other = pcbpt.render(cornell, seed=6, threads=2)
    for metric in ["relmse", "mse", "flip"]:
        assert pcbpt.compare(image, other, metric) > 0, metric
    brighter = image * 1.5
    assert pcbpt.compare(image, brighter, "mean_ratio") == pytest.approx(1.5, rel=1e-5)
    # relMSE as the crate defines it: (t - r)² / (r² + 0.01), averaged.
    r, t = image.astype(np.float64), brighter.astype(np.float32).astype(np.float64)
    assert pcbpt.compare(image, brighter) == pytest.approx(np.mean((t - r) ** 2 / (r * r + 0.01)), rel=1e-9)


def test_every_metric_at_once(image):
    metrics = pcbpt.compare(image, image * 2, None)
    assert set(metrics) == {"relmse", "mse", "mean_ratio", "reference_mean", "test_mean", "non_finite"}
    assert metrics["mean_ratio"] == pytest.approx(2)
    assert metrics["non_finite"] == 0
    with_nan = image.copy()
    with_nan[0, 0, 1] = np.nan
    assert pcbpt.compare(image, with_nan, None)["non_finite"] == 1


def test_images_of_other_shapes_or_metrics_are_refused(image):
    with pytest.raises(ValueError, match="image sizes differ"):
        pcbpt.compare(image, image[1:])
    with pytest.raises(ValueError, match=r"shape \(height, width, 3\)"):
        pcbpt.compare(image, image[..., :2])
    with pytest.raises(ValueError, match=r"shape \(height, width, 3\)"):
        pcbpt.compare(image[0], image[0])
    with pytest.raises(ValueError, match="at least one pixel"):
        pcbpt.compare(image[:0], image[:0])
    with pytest.raises(ValueError, match="unknown metric"):
        pcbpt.compare(image, image, "psnr")


def test_written_images_read_back(image, tmp_path):
    pcbpt.write_image(tmp_path / "a.exr", image)
    assert np.array_equal(pcbpt.read_image(tmp_path / "a.exr"), image)
    # Other array types and layouts are converted.
    pcbpt.write_image(tmp_path / "b.exr", np.asfortranarray(image.astype(np.float64)))
    assert np.array_equal(pcbpt.read_image(tmp_path / "b.exr"), image)
    pcbpt.write_image(tmp_path / "c.png", image)
    assert pcbpt.read_image(tmp_path / "c.png").shape == image.shape
    with pytest.raises(ValueError, match="unknown image format"):
        pcbpt.write_image(tmp_path / "d.bmp", image)


def test_an_unreadable_image_is_a_value_error(tmp_path):
    (tmp_path / "junk.exr").write_bytes(b"not an image")
    with pytest.raises(ValueError, match="junk.exr"):
        pcbpt.read_image(tmp_path / "junk.exr")
