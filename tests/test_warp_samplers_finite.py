"""Regression: MIS with the tabulated BRDF sampler produced NaN pixels when the tabulated pdf
near theta_l = 0 (it grows like 1/sin theta) overflowed float32 in the power heuristic."""
import numpy as np

from conftest import data_file, rgl_measured


def test_power_heuristic_never_nan():
    import warp as wp

    from warp_rbrdf import runtime  # noqa: F401  (Warp init, cache folder)
    from warp_rbrdf.integrator import power_heuristic

    @wp.kernel
    def k(pa: wp.array(dtype=float), pb: wp.array(dtype=float), out: wp.array(dtype=float)):
        i = wp.tid()
        out[i] = power_heuristic(pa[i], pb[i])

    pa = np.array([1e30, 1e30, np.inf, 1.0, 0.0, 2.0, 1e-30], np.float32)
    pb = np.array([1e30, 1.0, 1.0, np.inf, 0.0, 1.0, 1e-30], np.float32)
    out = wp.zeros(len(pa), dtype=float, device="cpu")
    wp.launch(k, dim=len(pa), inputs=[wp.array(pa, device="cpu"), wp.array(pb, device="cpu"), out], device="cpu")
    w = out.numpy()
    assert np.all(np.isfinite(w))
    np.testing.assert_allclose(w, [0.5, 1.0, 1.0, 0.0, 0.0, 0.8, 0.5], rtol=1e-6)


def test_mis_tabulated_render_is_finite():
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import parse_scene

    paper = data_file("rgl/paper_white_rgb.bsdf")
    studio = data_file("envmaps/studio_small_03_1k.hdr")
    scene = parse_scene(f"""
[camera]
origin = [0.0, 0.0, 3.0]
target = [0.0, 0.0, 0.0]
fov = 45.0
resolution = [48, 48]
[integrator]
spp = 64
seed = 132
pattern = "independent"
[materials.paper]
type = "measured"
file = "{paper}"
sampler = "mis-tabulated"
[[shapes]]
type = "sphere"
radius = 1.0
material = "paper"
[[lights]]
type = "envmap"
file = "{studio}"
""", path="<nan regression>")
    from lab import testing as T

    paper = scene.materials["paper"]
    paper.data = rgl_measured("paper_white_rgb", paper.incident)   # the file resampled once per session
    img = Renderer(T.common_kernel(scene)).render()   # the common test kernel (lab.testing)
    assert np.isfinite(img).all(), f"{int((~np.isfinite(img)).sum())} non-finite values"
    # the sphere's centre (the paper, lit by the map), not the visible map around it: a material
    # that evaluates to zero leaves it black while the background keeps the image's mean up
    centre = img[20:28, 20:28]
    assert centre.mean() > 0.1 * img.mean(), (centre.mean(), img.mean())
