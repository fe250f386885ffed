"""The Python package (python/bounce) against independent answers: the white furnace's closed form
through every method, the CLI's own CSV for the Cornell box, bounce's errors as exceptions, and
arrays that are the library's memory, not copies. Run by ctest (tests/python/run.sh)."""
import ctypes
import inspect
import os
import re
import subprocess
import sys

import numpy as np
import pytest

import bounce

SRC = os.environ.get("BOUNCE_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
EXE = os.environ.get("BOUNCE_EXE", os.path.join(SRC, "build", "bounce"))
CORNELL = os.path.join(SRC, "meshes", "cornell-box.obj")


def furnace(tmp_path, rho):
    """The shipped unit furnace (meshes/furnace-box.obj) with reflectance rho, Le 1."""
    obj = open(os.path.join(SRC, "meshes", "furnace-box.obj")).read()
    (tmp_path / "furnace-box.obj").write_text(obj)
    (tmp_path / "furnace-box.mtl").write_text("newmtl furnace\nKd %r %r %r\nKe 1 1 1\n" % (rho, rho, rho))
    return str(tmp_path / "furnace-box.obj")


@pytest.mark.parametrize("method", ["jacobi", "gauss-seidel", "neumann", "direct"])
@pytest.mark.parametrize("rho", [0.5, 0.9])
def test_furnace_every_method(tmp_path, method, rho):
    r = bounce.solve(furnace(tmp_path, rho), method=method, bounces=4, patches=150)
    assert r.method == method
    assert r.stop_reason.startswith("converged") or method == "direct"
    # L = Le / (1 - rho) on every patch and channel; K^k E = rho^k Le
    assert np.abs(r.L - 1.0 / (1.0 - rho)).max() <= 1e-6 / (1.0 - rho)
    assert len(r.terms) == 5
    for k, t in enumerate(r.terms):
        assert np.abs(t - rho ** k).max() <= 1e-6 * rho ** k, (k, np.abs(t - rho ** k).max())
    # rest is what the kept terms leave: sum_{k>4} rho^k = rho^5 / (1 - rho)
    assert np.abs(r.rest - rho ** 5 / (1 - rho)).max() <= 1e-6 / (1.0 - rho)


def test_cornell_equals_the_cli_csv(tmp_path):
    csv = tmp_path / "cb.csv"
    subprocess.run([EXE, "solve", CORNELL, "--unit", "mm", "--patches", "400", "--ff-visibility", "rays", "-q", "-o",
                    str(csv)], check=True, stderr=subprocess.DEVNULL)   # the subject is the binding, not visibility
    rows = [ln.split(",") for ln in csv.read_text().splitlines() if ln and not ln.startswith("#")]
    head, rows = rows[0], rows[1:]
    cols = [head.index(c) for c in ("L_R", "L_G", "L_B")]
    r = bounce.solve(CORNELL, unit="mm", patches=400, visibility="rays")
    assert r.patches == len(rows)
    area = head.index("area")
    mismatch = 0
    for i, row in enumerate(rows):
        for c, j in enumerate(cols):
            mismatch += row[j] != "%.9g" % r.L[i, c]   # the CSV's own format: every printed digit
        mismatch += abs(float(row[area]) - r.area[i] * 1e-6) > 1e-9 * float(row[area])   # printed to 10 digits
    assert mismatch == 0


def test_visibility_rays_equals_the_cli_and_exact_keeps_rows(tmp_path):
    """visibility= is --ff-visibility: "rays" equals `bounce solve --ff-visibility rays` to every
    printed digit; F by the exact visible parts (the default) keeps the Cornell box's rows within
    1e-4 of 1 where 32 shadow rays per pair leave some above; a bad name raises with it."""
    csv = tmp_path / "rays.csv"
    subprocess.run([EXE, "solve", CORNELL, "--unit", "mm", "--patches", "300", "--ff-visibility", "rays", "-q",
                    "-o", str(csv)], check=True, stderr=subprocess.DEVNULL)
    rows = [ln.split(",") for ln in csv.read_text().splitlines() if ln and not ln.startswith("#")]
    head, rows = rows[0], rows[1:]
    cols = [head.index(c) for c in ("L_R", "L_G", "L_B")]
    r = bounce.solve(CORNELL, unit="mm", patches=300, visibility="rays")
    assert r.patches == len(rows)
    assert all(row[j] == "%.9g" % r.L[i, c] for i, row in enumerate(rows) for c, j in enumerate(cols))
    exact = bounce.Scene.load(CORNELL, unit="mm", patches=300).form_factors().sum(1).max()
    rays = bounce.Scene.load(CORNELL, unit="mm", patches=300, visibility="rays").form_factors().sum(1).max()
    assert exact <= 1 + 1e-4 < rays, (exact, rays)
    with pytest.raises(bounce.BounceError) as e:
        bounce.solve(CORNELL, unit="mm", patches=100, visibility="sometimes")
    assert e.value.status == "EUSAGE" and "sometimes" in str(e.value)


def test_errors_raise_with_bounces_message(tmp_path):
    with pytest.raises(bounce.BounceError) as e:
        bounce.solve(str(tmp_path / "missing.obj"))
    assert e.value.status == "EIO" and "missing.obj" in str(e.value)
    bad = tmp_path / "bad.obj"
    bad.write_text("mtllib bad.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "bad.mtl").write_text("newmtl m\nKd 1.5 0.5 0.5\n")
    with pytest.raises(bounce.BounceError) as e:
        bounce.solve(str(bad))
    assert e.value.status == "EINPUT" and "Kd" in str(e.value) and "1.5" in str(e.value)
    with pytest.raises(bounce.BounceError) as e:
        bounce.solve(CORNELL, method="cholesky")
    assert e.value.status == "EUSAGE" and "cholesky" in str(e.value)


def test_messages_name_options_as_python_keywords():
    """bounce's messages name options as its C structs do, backquoted; Python shows keywords."""
    with pytest.raises(bounce.BounceError) as e:
        bounce.solve(CORNELL, unit="mm", transport="dense", patches=10**6)
    text = str(e.value)
    assert e.value.status == "ENOMEM" and "patch_size=" in text and "patches=" in text, text
    assert "`" not in text and "--" not in text, text


def test_the_package_as_installed_and_its_version():
    """Under tests/python/run.sh the package and the library are the ones pip and cmake --install put in
    the venv, found without PYTHONPATH or BOUNCE_LIBRARY; one version everywhere."""
    venv = os.environ.get("BOUNCE_INSTALLED_IN")
    if venv:
        assert os.path.realpath(bounce.__file__).startswith(os.path.realpath(venv)), bounce.__file__
        assert os.path.realpath(bounce.library_path()).startswith(os.path.realpath(venv))
        assert bounce.library_source() == "the prefix %s (cmake --install)" % sys.prefix
    cmake = open(os.path.join(SRC, "CMakeLists.txt")).read()
    assert bounce.__version__ == re.search(r"project\(bounce VERSION ([0-9.]+)", cmake).group(1)
    assert bounce.library_version() == bounce.__version__
    assert os.path.exists(os.path.join(os.path.dirname(bounce.__file__), "py.typed"))


def test_the_readme_python_lines_run(tmp_path):
    """README.md's Python lines, as a user pastes them (in a folder of their own with the meshes)."""
    readme = open(os.path.join(SRC, "README.md")).read()
    code = re.search(r"## From Python.*?```python\n(.*?)```", readme, re.S).group(1)
    os.symlink(os.path.join(SRC, "meshes"), tmp_path / "meshes")
    code = code.replace('bounces=10)', 'bounces=10, patches=300)').replace('(256, 256)', '(64, 64)')   # smaller
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    before, after = [np.array(ln.split("[")[1].split("]")[0].split(), float) for ln in out.stdout.splitlines()[:2]]
    assert after[0] > 1.5 * before[0]          # the light doubled
    assert (tmp_path / "relit.exr").exists() and (tmp_path / "relit.sheet.png").exists()


def test_sparse_form_factors_are_the_dense_ones_without_a_dense_copy():
    pytest.importorskip("scipy")
    s = bounce.Scene.load(CORNELL, unit="mm", patches=150)
    S = s.form_factors(sparse=True)
    F = s.form_factors()
    assert S.shape == F.shape and S.nnz == np.count_nonzero(F)
    assert np.array_equal(S.toarray(), F)
    r = bounce.solve(CORNELL, unit="mm", patches=150, transport="sparse")
    assert np.array_equal(r.form_factors(sparse=True).toarray(), r.form_factors())


def test_k_as_a_scipy_linear_operator():
    """scipy's GMRES on bounce's K reaches bounce's own L; K E is the KE term exactly; under the hierarchy too."""
    spla = pytest.importorskip("scipy.sparse.linalg")
    for transport in ("dense", "hierarchical"):
        r = bounce.solve(CORNELL, unit="mm", patches=150, transport=transport, tol=1e-12, method="jacobi")
        K = bounce.as_linear_operator(r)
        n3 = 3 * r.patches
        assert K.shape == (n3, n3)
        assert np.array_equal(K.matvec(r.emission.ravel()), r.terms[1].ravel())
        A = spla.LinearOperator((n3, n3), matvec=lambda x: x - K.matvec(x), dtype=np.float64)
        L, info = spla.gmres(A, r.emission.ravel(), tol=1e-12, atol=0, restart=60, maxiter=100)
        assert info == 0
        assert np.abs(L - r.L.ravel()).max() <= 1e-8 * np.abs(r.L).max(), transport
        F = bounce.as_linear_operator(r, reflectance=False)
        ones = np.ones(n3)
        assert np.allclose(r.reflectance.ravel() * F.matvec(ones), K.matvec(ones), rtol=1e-15, atol=0)


def test_images_in_memory():
    """render(): without the gather each pixel (1 sample) is the radiance of the patch it sees, L is the
    sum of the other layers, and the final gather's L is near the flat one's on average."""
    r = bounce.solve(CORNELL, unit="mm", patches=300, bounces=2, visibility="rays")
    flat = r.render(size=(48, 40), spp=1, gather=False)
    assert list(flat) == ["E", "KE", "K2E", "rest", "L"]
    assert all(a.shape == (40, 48, 3) and a.dtype == np.float32 and not a.flags.writeable for a in flat.values())
    values = set(np.float32(r.L).ravel().tolist()) | {0.0}
    assert set(flat["L"].ravel().tolist()) <= values              # every pixel a patch's L (or a miss)
    total = flat["E"] + flat["KE"] + flat["K2E"] + flat["rest"]
    assert np.abs(total - flat["L"]).max() <= 1e-5 * flat["L"].max()
    gathered = r.render(size=(48, 40))
    assert abs(gathered["L"].mean() / flat["L"].mean() - 1) < 0.1
    with pytest.raises(bounce.BounceError):
        r.render(size=(0, 10))


def test_the_tracer_from_python_agrees_with_the_solve_by_its_own_errors():
    """trace(): the path tracer, which shares only the scene with the solve, estimates KE and K2E of
    every patch; the solve's values sit within its standard errors (z over ~860 values: rms near 1,
    mean near 0); the same seed gives the same numbers; trace_image() gives every layer per pixel, L
    the sum of the others; a Scene traces without solving; bad samples raise naming them."""
    r = bounce.solve(CORNELL, unit="mm", patches=300, bounces=2, visibility="rays")
    t = r.trace(spp=256, bounces=2)
    assert t.layers == ["E", "KE", "K2E", "rest", "L"]
    for k, name in ((1, "KE"), (2, "K2E")):
        ok = t.error[name] > 0
        z = (r.terms[k] - t.mean[name])[ok] / t.error[name][ok]
        assert ok.sum() > 500 and 0.7 < np.sqrt((z ** 2).mean()) < 1.4 and abs(z.mean()) < 0.25, (name, z.mean())
    assert np.array_equal(r.trace(spp=256, bounces=2, threads=1).mean["KE"], t.mean["KE"])
    im = r.trace_image(size=(32, 24), spp=4, bounces=1)
    assert list(im.mean) == ["E", "KE", "rest", "L"] and im.mean["L"].shape == (24, 32, 3)
    total = im.mean["E"] + im.mean["KE"] + im.mean["rest"]
    assert np.abs(total - im.mean["L"]).max() <= 1e-4 * im.mean["L"].max() and im.error["L"].min() >= 0
    s = bounce.Scene.load(CORNELL, unit="mm", patches=100)
    assert s.trace(spp=4, bounces=0).mean["E"].max() == pytest.approx(17.0, rel=1e-6)   # the light's Le
    for kw, needle in ((dict(spp=0), "spp 0"), (dict(spp=-2), "spp -2"), (dict(bounces=99), "bounces 99")):
        with pytest.raises(bounce.BounceError, match=needle):
            r.trace(**kw)
    with pytest.raises(bounce.BounceError, match="width and height"):
        r.trace_image(size=(0, 8))


def test_crosscheck_from_python_is_the_clis(tmp_path):
    """bounce.crosscheck: the verdict line's figures are the CLI's for the same scene, seed and samples
    (a noisy ray-visibility F, which fails: a failed check is an answer, not an exception); the arrays
    give the worst z again; on exact F the check passes; bad options raise naming them."""
    args = dict(unit="mm", patches=200, spp=256, visibility="rays", seed=3)
    c = bounce.crosscheck(CORNELL, **args)
    out = subprocess.run([EXE, "crosscheck", CORNELL, "--unit", "mm", "--patches", "200", "--spp", "256",
                          "--ff-visibility", "rays", "--seed", "3"], capture_output=True, text=True).stdout
    line = [ln for ln in out.splitlines() if ln.startswith("verdict:")][0]
    v = dict(kv.split("=") for kv in line.split()[2:])
    assert line.split()[1] == ("pass" if c.passed else "fail")
    assert v["within"] == "%d/%d" % (c.within, c.family)
    for k in ("worst_z", "worst_z_raw", "power_worst_z", "crit"):
        assert float(v[k]) == pytest.approx(getattr(c, k), abs=1e-4), k
    # the worst judged entry is among the arrays' (entries with too few hits are shown, not judged)
    zs = np.concatenate([np.abs(c.z(k)).ravel() for k in c.layers])
    assert np.isclose(zs, c.worst_z_raw, rtol=1e-9).any() and np.nanmax(zs) >= c.worst_z_raw
    assert c.layers == ["E", "KE", "K2E", "K3E", "rest", "L"] and c.radiosity["L"].shape == (c.family // 18, 3)
    assert bounce.crosscheck(CORNELL, unit="mm", patches=200, spp=256).passed
    for kw, needle in ((dict(model="mesh"), "model 'mesh'"), (dict(alpha=2.0), "alpha 2"),
                       (dict(spp=-1), "spp -1")):
        with pytest.raises(bounce.BounceError, match=needle):
            bounce.crosscheck(CORNELL, unit="mm", patches=50, **kw)


def test_a_study_from_python_is_the_clis_table(tmp_path):
    """bounce.study: the truncation study's rows equal the CLI's CSV for the same settings (errors are
    deterministic: every printed digit), the a priori bound holds on every truncated row (err_inf <=
    bound), the error falls with each bounce; a name value (ff) and a bad vary are handled."""
    s = bounce.study(CORNELL, "bounces", [0, 1, 2, 3, 5], unit="mm", patches=200, visibility="rays")
    csv = tmp_path / "st.csv"
    subprocess.run([EXE, "study", CORNELL, "--unit", "mm", "--patches", "200", "--ff-visibility", "rays",
                    "--vary", "bounces=0,1,2,3,5", "-q", "-o", str(csv)], check=True, stderr=subprocess.DEVNULL)
    lines = [ln.split(",") for ln in csv.read_text().splitlines() if ln and not ln.startswith("#")]
    head, rows = lines[0], lines[1:]
    assert len(rows) == len(s) and [r[head.index("method")] for r in rows] == s.method
    for col in ("x", "patches", "iterations", "err_inf", "err_max_rel", "err_rms_rel", "bound", "estimate"):
        want = [float(r[head.index(col)]) for r in rows]
        got = ["%.9g" % v for v in s.columns[col]]
        assert got == ["%.9g" % v for v in want], col
    t = s.rows("truncated")
    assert list(t["x"]) == [0, 1, 2, 3, 5] and np.all(t["err_inf"] <= t["bound"])
    assert np.all(np.diff(t["err_max_rel"]) < 0)
    assert len(bounce.study(CORNELL, "ff", ["analytic", "hemisphere"], unit="mm", patches=60, visibility="rays")) == 2
    with pytest.raises(bounce.BounceError, match="vary 'colour'"):
        bounce.study(CORNELL, "colour", [1], unit="mm", patches=60)
    with pytest.raises(bounce.BounceError, match="'phong'"):
        bounce.study(CORNELL, "ff", ["phong"], unit="mm", patches=60)


def test_the_type_hints_names_are_the_librarys():
    """bounce._names (Literal types for method, transport, unit, ...) is what scripts/python_names.py
    makes from the library's tables now: a vocabulary changed in C without regenerating it fails here."""
    import importlib.util
    import typing
    import bounce._names as hints
    spec = importlib.util.spec_from_file_location("python_names", os.path.join(SRC, "scripts", "python_names.py"))
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    assert open(hints.__file__).read() == gen.text()
    for v in gen.VOCABULARIES:
        got = list(typing.get_args(getattr(hints, v.capitalize() + "Name")))
        assert got == bounce.names(v) + (["auto"] if v == "method" else []), v


def test_the_cli_solve_options_by_their_names(tmp_path):
    """max_iter, atol, stop, seed, precision, storage, cache, ff as `bounce solve` takes them."""
    kw = dict(unit="mm", patches=100, visibility="rays")
    assert bounce.solve(CORNELL, precision="double", **kw).transport == "dense-double"
    assert bounce.solve(CORNELL, storage="sparse", **kw).transport == "csr-float"
    with pytest.raises(bounce.BounceError) as e:
        bounce.solve(CORNELL, max_iter=2, **kw)
    assert e.value.status == "ENOTCONV" and "within 2 iterations" in str(e.value)
    a = bounce.solve(CORNELL, stop="bound", atol=1e-9, **kw)
    assert a.iterations > bounce.solve(CORNELL, **kw).iterations   # the bound stops later than the residual
    cache = tmp_path / "ff.bnff"
    first = bounce.solve(CORNELL, cache=cache, **kw)
    stamp = os.stat(cache).st_mtime_ns
    again = bounce.solve(CORNELL, cache=str(cache), **kw)          # read, not written again
    assert os.stat(cache).st_mtime_ns == stamp and np.array_equal(first.L, again.L)
    h5, h6 = (bounce.solve(CORNELL, ff="hemisphere", seed=s, **kw).L for s in (5, 6))
    assert not np.array_equal(h5, h6) and np.abs(h5 - h6).max() < 0.2 * h5.max()   # the seed is used
    for bad, needle in ((dict(stop="never"), "stop 'never'"), (dict(precision="half"), "precision 'half'"),
                        (dict(storage="tree"), "storage 'tree'"), (dict(ff="magic"), "ff 'magic'"),
                        (dict(colour=1), "unknown option colour"), (dict(atol=-1), "atol -1"),
                        (dict(max_iter=-3), "max_iter -3")):
        with pytest.raises(bounce.BounceError) as e:
            bounce.solve(CORNELL, **kw, **bad)
        assert needle in str(e.value), str(e.value)


def test_arrays_are_read_only_copies_of_the_librarys():
    r = bounce.solve(CORNELL, unit="mm", patches=300, visibility="rays")
    lib, h, n = r._lib, r._h, r.patches
    lib_L = np.ctypeslib.as_array(lib.bn_flat_L(h), shape=(n, 3))
    assert np.array_equal(r.L, lib_L) and np.array_equal(r.terms[2], np.ctypeslib.as_array(lib.bn_flat_term(h, 2), shape=(n, 3)))
    for a in (r.L, r.terms[1], r.rest, r.emission, r.reflectance, r.area):
        assert not a.flags.writeable
    with pytest.raises(ValueError):   # an edit is an error, never silently ignored
        r.reflectance[:] = 0.1
    s = bounce.Scene.load(CORNELL, unit="mm", patches=100)
    with pytest.raises(ValueError):
        s.reflectance[:] = 0.1
    L = r.L
    del r
    assert np.isfinite(L).all() and L.max() > 1


def _edited_cornell(tmp_path, light, red):
    """The Cornell box with the light's Ke and the red wall's Kd replaced, as files of its own."""
    src = open(os.path.join(SRC, "meshes", "cornell-box.mtl")).read()
    src = src.replace("Ke 17 12 4", "Ke %g %g %g" % tuple(light)).replace("Kd 0.63 0.065 0.05", "Kd %g %g %g" % tuple(red))
    (tmp_path / "cornell-box.mtl").write_text(src)
    obj = open(CORNELL).read()
    (tmp_path / "cornell-box.obj").write_text(obj)
    return str(tmp_path / "cornell-box.obj")


def test_relight_equals_a_fresh_solve_of_the_edited_file(tmp_path):
    kw = dict(unit="mm", patches=200, transport="dense", tol=1e-12, bounces=4, visibility="rays")
    r = bounce.solve(CORNELL, **kw)
    L_before = r.L
    assert r.relight(Le={"light": (34, 24, 8)}, rho={"red": (0.1, 0.6, 0.1)}) is r
    fresh = bounce.solve(_edited_cornell(tmp_path, (34, 24, 8), (0.1, 0.6, 0.1)), **kw)
    assert np.abs(r.L - L_before).max() > 0.5 * np.abs(L_before).max()   # it changed ...
    for a, b in zip(r.terms + [r.rest, r.L, r.emission, r.reflectance], fresh.terms + [fresh.rest, fresh.L, fresh.emission, fresh.reflectance]):
        assert np.abs(a - b).max() <= 1e-6 * np.abs(b).max()          # ... to a fresh solve's answer
    assert r.relight_gain > 2 * 0.6 / 0.065 * 0.9
    again = r.relight(Le={"light": 0})   # the light off: no light at all
    assert np.abs(again.L).max() == 0 and L_before.max() > 1   # arrays taken before keep their answer


@pytest.fixture(scope="module")
def solved_once():
    return bounce.solve(CORNELL, unit="mm", patches=100, visibility="rays")


@pytest.mark.parametrize("kw, needle", [
    (dict(Le={"blue": 1}), "'blue' is not a material"),
    (dict(rho={"red": 1.5}), "1.5"),
    (dict(Le={"light": -2}), "-2"),
    (dict(Le={"light": (1, 2)}), "2 values"),
    (dict(rho={"red": "dark"}), "dark"),
    (dict(rho={3: 0.5}), "not 3"),
    (dict(Le={"light": float("nan")}), "nan"),
])
def test_bad_relights_raise_naming_the_value(kw, needle, solved_once):
    r = solved_once   # one solve for every bad value: each refusal must leave it as it was
    L = r.L.copy()
    with pytest.raises(bounce.BounceError) as e:
        r.relight(**kw)
    assert needle in str(e.value), str(e.value)
    assert np.array_equal(r.L, L)   # nothing changed


def test_form_factors_rows_and_reciprocity(tmp_path):
    # the closed furnace cube (no occluders): every row of F sums to 1 (float storage: 1e-6)
    f = bounce.solve(furnace(tmp_path, 0.5), patches=150).form_factors()
    assert np.abs(f.sum(axis=1) - 1).max() <= 1e-6
    # the Cornell box, open at the front: rows at most 1 plus its visibility noise (0.3%)
    r = bounce.solve(CORNELL, unit="mm", patches=300)
    F = r.form_factors()
    assert F.shape == (r.patches, r.patches) and (F >= 0).all()
    assert F.sum(axis=1).max() <= 1.003
    # reciprocity A_i F_ij = A_j F_ji (float storage: 1e-6 relative, plus the occluded pairs' noise)
    AF = r.area[:, None] * F
    assert np.abs(AF - AF.T).max() <= 1e-3 * AF.max()


def test_a_python_operator_reproduces_the_dense_solve():
    r = bounce.solve(CORNELL, unit="mm", patches=300, method="jacobi", tol=1e-13, bounces=3, visibility="rays")
    F = r.form_factors()
    rho = r.reflectance
    op = bounce.Operator(r.patches, lambda x: rho * (F @ x))
    mine = bounce.solve(op, emission=np.array(r.emission), method="jacobi", tol=1e-13, bounces=3)
    assert mine.transport == "caller" and mine.method == "jacobi"
    assert np.abs(mine.L - r.L).max() <= 1e-12 * np.abs(r.L).max()
    for k in range(4):
        assert np.abs(mine.terms[k] - r.terms[k]).max() <= 1e-12 * np.abs(r.L).max()
    # with rows, Gauss-Seidel runs on it too, and agrees with the built-in Gauss-Seidel
    gs = bounce.solve(CORNELL, unit="mm", patches=300, method="gauss-seidel", tol=1e-13, bounces=3, visibility="rays")
    op_rows = bounce.Operator(r.patches, lambda x: rho * (F @ x), row=lambda i, x: rho[i] * (F[i] @ x))
    mine_gs = bounce.solve(op_rows, emission=np.array(r.emission), tol=1e-13, bounces=3)
    assert mine_gs.method == "gauss-seidel"
    assert np.abs(mine_gs.L - gs.L).max() <= 1e-12 * np.abs(gs.L).max()
    # and the Neumann series
    mine_n = bounce.solve(op, emission=np.array(r.emission), method="neumann", tol=1e-13, bounces=3)
    assert np.abs(mine_n.L - r.L).max() <= 1e-11 * np.abs(r.L).max()


def test_an_operator_that_raises_stops_the_solve():
    def broken(x):
        raise ValueError("my operator broke")
    with pytest.raises(ValueError, match="my operator broke"):
        bounce.solve(bounce.Operator(4, broken), emission=np.ones((4, 3)))


def test_the_doc_example_runs(tmp_path):
    """doc/python_example.py (at 200 patches): its table says what the series must: the shares add up
    to L, and the truncation error falls with every term kept; its contact sheet has every layer."""
    env = dict(os.environ)
    out = subprocess.run([sys.executable, os.path.join(SRC, "doc", "python_example.py"), str(tmp_path / "ex"), "200"],
                         capture_output=True, text=True, env=env, check=True).stdout
    assert "contact sheet: E KE K2E K3E rest L, 960 x 320 pixels" in out
    rows = [ln.split() for ln in out.splitlines() if ln[:2].strip().isdigit()]
    assert len(rows) == 11
    errors = [float(r[3]) for r in rows]
    assert all(b < a for a, b in zip(errors, errors[1:]))
    ratios = [float(q) for q in out.split("last three):")[1].split()[:3]]
    assert all(0 < q < 1 for q in ratios)


def test_ctrl_c_stops_the_c_loops():
    """SIGINT during a long solve (form factors of 6,000 patches take tens of seconds) stops bounce's
    loops within seconds and comes out as KeyboardInterrupt; the interpreter's handler is back after."""
    import signal
    import time
    code = ("import bounce, signal, sys\n"
            "try:\n"
            "    bounce.solve(%r, unit='mm', patches=6000, transport='dense')\n"
            "    print('finished')\n"
            "except KeyboardInterrupt as e:\n"
            "    print('interrupted:', e)\n"
            "    print('handler back:', signal.getsignal(signal.SIGINT) is signal.default_int_handler)\n" % CORNELL)
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                         env=dict(os.environ))
    # until the child has spent 2 s of CPU (import and meshing take a fraction of that; the form
    # factors' loops use every core), not a fixed sleep: under load it may take longer to get there
    tick = os.sysconf("SC_CLK_TCK")
    for _ in range(600):
        stat = open("/proc/%d/stat" % p.pid).read().rsplit(")", 1)[1].split()
        if (int(stat[11]) + int(stat[12])) / tick >= 2 or p.poll() is not None:
            break
        time.sleep(0.05)
    t0 = time.time()
    p.send_signal(signal.SIGINT)
    out, _ = p.communicate(timeout=60)
    took = time.time() - t0
    assert "interrupted: bounce:" in out and "handler back: True" in out, out
    assert took < 15, took


def test_bake_from_python_equals_the_cli(tmp_path):
    """A bake from Python and `bounce bake` of the same scene and options write the same vertices and
    colours (the glTF's float attributes compared value by value; the header may differ in provenance),
    with the patches' values (--gather none) and gathered on the refined mesh (the defaults, a budget)."""
    import json
    import struct

    def glb_floats(path, attr):
        d = open(path, "rb").read()
        jl = struct.unpack_from("<I", d, 12)[0]
        g = json.loads(d[20:20 + jl])
        binary = d[28 + jl:]
        a = g["accessors"][g["meshes"][0]["primitives"][0]["attributes"][attr]]
        v = g["bufferViews"][a["bufferView"]]
        return np.frombuffer(binary, dtype="<f4", count=3 * a["count"], offset=v["byteOffset"])

    r = bounce.solve(CORNELL, unit="mm", patches=200, visibility="rays")
    for gather, extra in ((False, ["--gather", "none"]), (True, ["--bake-vertices", "600"])):
        mine = tmp_path / ("py-%s.glb" % gather)
        r.bake(str(mine), gather=gather, vertices=600 if gather else None)
        cli = tmp_path / ("cli-%s.glb" % gather)
        subprocess.run([EXE, "bake", CORNELL, "--unit", "mm", "--patches", "200", "--ff-visibility", "rays",
                        "--per-bounce", "-q", "-o", str(cli)] + extra, check=True, stderr=subprocess.DEVNULL)
        for attr in ("POSITION", "COLOR_0", "_L", "_E", "_KE", "_K2E", "_K3E", "_REST"):
            a, b = glb_floats(mine, attr), glb_floats(cli, attr)
            assert a.shape == b.shape and np.array_equal(a, b), (gather, attr)
    assert glb_floats(tmp_path / "py-True.glb", "POSITION").size > glb_floats(tmp_path / "py-False.glb", "POSITION").size
    with pytest.raises(bounce.BounceError) as e:   # the refinement is the gathered element mesh's
        r.bake(str(tmp_path / "z.glb"), gather=False, vertices=10)
    assert "vertices" in str(e.value)
    with pytest.raises(bounce.BounceError) as e:
        r.bake(str(tmp_path / "x.stl"))
    assert e.value.status == "EUSAGE" and ".stl" in str(e.value)
    with pytest.raises(bounce.BounceError) as e:   # the mesh's names come from the library
        r.bake(str(tmp_path / "y.glb"), mesh="faces")
    assert e.value.status == "EUSAGE" and "'faces'" in str(e.value) and "elements|input" in str(e.value)
    assert not (tmp_path / "y.glb").exists()


def test_names_are_the_librarys_and_the_cli_takes_them():
    """bounce.names hands out the library's tables; the CLI refuses a made-up value
    listing the same names."""
    assert bounce.names("method") == ["jacobi", "gauss-seidel", "neumann", "direct"]
    assert bounce.names("gather") == ["final", "none"]
    assert bounce.names("mesh") == ["elements", "input"]
    assert "hierarchical" in bounce.names("transport")
    with pytest.raises(bounce.BounceError):
        bounce.names("colour")
    for cmd, flag, vocabulary in (("solve", "--method", "method"), ("solve", "--stop", "stop"),
                                  ("trace", "--strategy", "strategy"), ("crosscheck", "--model", "model"),
                                  ("bake", "--mesh", "mesh"), ("bounces", "--gather", "gather")):
        r = subprocess.run([EXE, cmd, CORNELL, flag, "bogus"], capture_output=True, text=True)
        assert r.returncode == 2 and "|".join(bounce.names(vocabulary)) in r.stderr, (cmd, flag, r.stderr)


def test_images_from_python_equal_the_cli(tmp_path):
    """r.images writes what `bounce bounces` writes for the same solve and camera: every layer's mean
    (read back by OpenImageIO's oiiotool, a reader of its own) is the same number."""
    import shutil
    oiio = shutil.which("oiiotool")
    if not oiio:
        pytest.skip("no oiiotool (Debian's openimageio-tools, which scripts/setup.sh installs)")
    r = bounce.solve(CORNELL, unit="mm", patches=400, visibility="rays")
    mine = tmp_path / "py.exr"
    r.images(str(mine), size=(96, 96), previews=False)
    cli = tmp_path / "cli.exr"
    subprocess.run([EXE, "bounces", CORNELL, "--unit", "mm", "--patches", "400", "--ff-visibility", "rays", "--size",
                    "96x96", "--no-previews", "-q", "-o", str(cli)], check=True, stderr=subprocess.DEVNULL)

    def means(p):
        out = subprocess.run([oiio, "--stats", str(p)], capture_output=True, text=True, check=True).stdout
        return [ln.split("Stats Avg:")[1].split() for ln in out.splitlines() if "Stats Avg:" in ln]

    a, b = means(mine), means(cli)
    assert a and a == b
    with pytest.raises(bounce.BounceError) as e:
        r.images(str(tmp_path / "x.exr"), eye=(278, 273, -800), look=(278, 273, -800))
    assert e.value.status in ("EUSAGE", "EINPUT") and "eye" in str(e.value)


def test_scene_arrays_form_factors_and_solve(tmp_path):
    s = bounce.Scene.load(furnace(tmp_path, 0.9), patches=150)
    assert s.patches >= 150 and s.area.shape == (s.patches,)
    assert abs(s.area.sum() - 6.0) < 1e-12                      # the unit cube's six faces
    assert np.allclose(np.linalg.norm(s.normal, axis=1), 1)
    assert (s.reflectance == 0.9).all() and (s.emission == 1).all()
    F = s.form_factors()
    assert np.abs(F.sum(axis=1) - 1).max() <= 1e-6 and s.diagnostics["row_sum_max"] <= 1 + 1e-6
    # an empty convex room: no pair is occluded, so no shadow ray is cast
    assert s.diagnostics["rays"] == 0 and s.diagnostics["occluded_fraction"] == 0
    assert s.diagnostics["k_norm_inf"] == pytest.approx(0.9, abs=1e-6)
    c = bounce.Scene.load(CORNELL, unit="mm", patches=150, visibility="rays")
    c.form_factors()   # the blocks hide pairs: rays are cast, and counted
    assert c.diagnostics["rays"] > 0 and 0 < c.diagnostics["occluded_fraction"] < 1
    r = bounce.solve(s, bounces=2)
    assert r.patches == s.patches and np.abs(r.L - 10).max() <= 1e-5


def test_a_scene_keeps_its_F_across_solves_and_relights():
    """bounce.solve(scene) solves on the scene's own K: built once (its report's seconds, to the bit,
    unchanged by later solves), answers equal to a solve of the file; a relight shows in the scene."""
    s = bounce.Scene.load(CORNELL, unit="mm", patches=150, transport="dense")
    F = s.form_factors()
    d0 = (ctypes.c_double * 12)()
    s._lib.bn_flat_ff_diagnostics(s._h, d0)
    a = bounce.solve(s, bounces=3, tol=1e-10)
    b = bounce.solve(s, method="jacobi", bounces=5, tol=1e-10)
    d1 = (ctypes.c_double * 12)()
    s._lib.bn_flat_ff_diagnostics(s._h, d1)
    assert list(d0) == list(d1) and d0[9] > 0                      # the same assembly: F not built again
    fresh = bounce.solve(CORNELL, unit="mm", patches=150, transport="dense", bounces=3, tol=1e-10)
    assert np.abs(a.L - fresh.L).max() <= 1e-8 * fresh.L.max() and len(b.terms) == 6
    assert np.abs(b.L - a.L).max() <= 1e-8 * a.L.max()             # a's arrays survive b's solve
    b.relight(rho={"red": 0.5})
    assert (s.reflectance[s.reflectance[:, 1] == 0.5].shape[0] > 0)   # the scene follows the relight
    assert np.array_equal(s.form_factors(), F)
    with pytest.raises(bounce.BounceError) as e:   # the solver's options reach a scene's solve ...
        bounce.solve(s, max_iter=2)
    assert e.value.status == "ENOTCONV" and "within 2 iterations" in str(e.value)
    with pytest.raises(bounce.BounceError) as e:   # ... F's are the scene's, never silently dropped
        bounce.solve(s, cache="elsewhere.bnff")
    assert "Scene.load" in str(e.value) and not os.path.exists("elsewhere.bnff")
    del a, b
    assert s.patches > 0 and np.isfinite(s.area).all()           # the results did not free the scene's handle


def test_monitor_history(tmp_path):
    """The solver's monitor as arrays: in the furnace Jacobi's residual falls by exactly rho each
    iteration (K = rho F with rows of F summing to 1, so the error is rho^k times the first), and
    the last row is the result's own residual."""
    rho = 0.9
    r = bounce.solve(furnace(tmp_path, rho), method="jacobi", patches=150, tol=1e-10)
    h = r.history
    assert len(h["iteration"]) == r.iterations + 1 and h["iteration"][0] == 0
    assert h["residual_max"][-1] == r.residual
    q = h["residual_max"][2:12] / h["residual_max"][1:11]
    assert np.abs(q - rho).max() <= 1e-3, q
    assert (h["error_bound"][1:] >= 0).all()


# ---- no silent wrong answers (issue: every failure loud, every option checked) ----

def _nan_operator(K, at):
    """y = K x with a NaN in its at-th output (patch 1, channel G); counts its calls."""
    calls = [0]

    def apply(x):
        calls[0] += 1
        y = K @ x
        if calls[0] == at:
            y[1, 1] = np.nan
        return y
    return apply, calls


def _nan_every_application(K, E):
    for method in ("jacobi", "neumann", "gauss-seidel"):
        rows = (lambda i, x: K[i] @ x) if method == "gauss-seidel" else None
        clean, calls = _nan_operator(K, 0)
        r = bounce.solve(bounce.Operator(K.shape[0], clean, rows), emission=E, method=method, tol=1e-10)
        assert np.isfinite(r.L).all()
        total = calls[0]
        assert total > 4
        for at in range(1, total + 1):
            bad, _ = _nan_operator(K, at)
            with pytest.raises(bounce.BounceError) as e:
                bounce.solve(bounce.Operator(K.shape[0], bad, rows), emission=E, method=method, tol=1e-10)
            assert e.value.status == "ENUMERIC", (method, at, str(e.value))
            assert ("call %d gave a non-finite" % at) in str(e.value) and "patch 1, channel G" in str(e.value)


def test_nan_from_a_user_operator_at_every_application():
    """A NaN at any application stops every method (before: dropped by the monitor, 'converged')."""
    rng = np.random.default_rng(7)
    F = rng.random((6, 6))
    F /= F.sum(axis=1, keepdims=True)
    _nan_every_application(0.6 * F, np.ones((6, 3)))


def test_nan_from_a_file_scenes_operator_at_every_application(tmp_path):
    s = bounce.Scene.load(furnace(tmp_path, 0.5), patches=24, visibility="rays")
    K = 0.5 * s.form_factors()
    _nan_every_application(K, np.array(s.emission))


@pytest.mark.parametrize("kw, needle", [
    (dict(tol=0), "tol 0"), (dict(tol=-1), "tol -1"), (dict(tol=float("nan")), "tol nan"),
    (dict(threads=-1), "threads -1"), (dict(patches=-5), "patches -5"), (dict(unit=None), "unit must be a string"),
    (dict(bounces=10**6), "bounces 1000000"), (dict(eps=-1), "eps -1"), (dict(patch_size=-2), "patch_size -2"),
    (dict(unit="furlong"), "unit 'furlong'"), (dict(method="cholesky"), "method 'cholesky'"),
    (dict(patches=2**63), "patches 9223372036854775808 is above")])
def test_bad_options_raise_naming_the_value(kw, needle):
    """Each bad value is refused before any work (a bounces of 10**6 used to run for minutes)."""
    with pytest.raises(bounce.BounceError) as e:
        bounce.solve(CORNELL, **kw)
    assert needle in str(e.value), str(e.value)
    assert e.value.status == "EUSAGE"


def test_bad_operators_raise_naming_what_they_are():
    E = np.ones((4, 3))
    with pytest.raises(bounce.BounceError, match="patches 0: an operator needs at least one patch"):
        bounce.solve(bounce.Operator(0, lambda x: x), emission=np.ones((0, 3)))
    with pytest.raises(bounce.BounceError, match="returned None"):
        bounce.solve(bounce.Operator(4, lambda x: None), emission=E)
    with pytest.raises(bounce.BounceError, match=r"returned shape \(4,\), not \(4, 3\)"):
        bounce.solve(bounce.Operator(4, lambda x: x[:, 0]), emission=E)
    with pytest.raises(bounce.BounceError, match="tol -1"):
        bounce.solve(bounce.Operator(4, lambda x: 0.5 * x), emission=E, tol=-1)
    with pytest.raises(bounce.BounceError, match="threads -1"):
        bounce.solve(bounce.Operator(4, lambda x: 0.5 * x), emission=E, threads=-1)


def test_negative_bounces_keep_no_terms_for_files_and_operators(tmp_path):
    """bounces < 0 means no terms in both paths (the file path used to keep E)."""
    r = bounce.solve(furnace(tmp_path, 0.5), patches=24, bounces=-1, visibility="rays")
    assert r.terms == [] and r.rest is None and abs(r.L[0, 0] - 2) < 1e-5
    m = bounce.solve(bounce.Operator(4, lambda x: 0.5 * x), emission=np.ones((4, 3)), bounces=-1)
    assert m.terms == [] and abs(m.L[0, 0] - 2) < 1e-5


def test_the_options_layout_is_checked_against_the_library(monkeypatch):
    """A struct that differs from the library's by one field is refused before any call."""
    assert bounce.library_version().count(".") == 2
    assert bounce._lib.bn_flat_opts_size() == ctypes.sizeof(bounce._Opts)

    class Longer(ctypes.Structure):
        _fields_ = bounce._Opts._fields_ + [("extra", ctypes.c_int)]
    monkeypatch.setattr(bounce, "_Opts", Longer)
    with pytest.raises(bounce.BounceError, match="lays bn_flat_opts out in .* bytes, this package in"):
        bounce._check_layout(bounce._lib, "libbounce.so")


# The command line's flags with no keyword of the same name, and why (every other flag of solve, bounces and
# bake is a keyword of bounce.solve / Scene.load, Result.images / render, or Result.bake).
NOT_KEYWORDS = {
    "output": "the path argument of solve's CSV (Result holds the arrays), images() and bake()",
    "quiet": "progress=False (the default)", "help": "help(bounce)", "version": "bounce.__version__",
    "set-rho": "Result.relight(rho=...)", "set-Le": "Result.relight(Le=...)",
    "log": "Result.history (the convergence table as arrays)",
    "no-previews": "images(previews=False)", "patches-out": "Result's per-patch arrays (area, L, terms)",
    "for": "a CLI hint; for Blender's PLY: bake(ldr=True)",
}


def _cli_flags(command):
    text = subprocess.run([EXE, command, "--help"], capture_output=True, text=True).stdout
    return sorted(set(re.findall(r"^\s+(?:-\w, )?--([a-zA-Z][\w-]*)", text, re.M)))


@pytest.mark.skipif(not os.path.exists(EXE), reason="no bounce executable (BOUNCE_EXE)")
def test_every_cli_option_of_solve_bounces_and_bake_is_a_keyword():
    """Each flag of `bounce solve`, `bounce bounces` and `bounce bake --help` is a keyword of the matching Python
    call by the same name (dashes as underscores), or listed above with the way Python does it."""
    solve_kw = set(inspect.signature(bounce.solve).parameters) | set(bounce._MORE) | {"ff_visibility"} | \
        set(bounce.names("scene_options")) | set(bounce.names("solve_options"))
    image_kw = set(inspect.signature(bounce.Result.images).parameters) | set(bounce.names("image_options"))
    bake_kw = set(inspect.signature(bounce.Result.bake).parameters) | set(bounce.names("bake_options")) | \
        {"bake_vertices"}
    missing = []
    for command, kws in (("solve", solve_kw), ("bounces", solve_kw | image_kw), ("bake", solve_kw | bake_kw)):
        flags = _cli_flags(command)
        assert len(flags) > 25, (command, flags)
        missing += ["%s --%s" % (command, f) for f in flags if f.replace("-", "_") not in kws and f not in NOT_KEYWORDS]
    assert not missing, missing


def test_further_options_take_effect_and_bad_ones_name_the_value(tmp_path):
    kw = dict(unit="mm", patches=60, visibility="rays", bounces=2)
    a = bounce.solve(CORNELL, **kw)
    b = bounce.solve(CORNELL, no_contacts=True, **{**kw, "visibility": "exact", "ff_visibility": "rays"})
    assert b.patches < a.patches   # the blocks' contact lines cut the floor (no_contacts: not cut)
    with pytest.raises(bounce.BounceError, match="name the same option"):
        bounce.solve(CORNELL, ff_visibility="exact", **kw)
    for bad, needle in ((dict(contact_gap=-1), "contact_gap=: -1 is outside"), (dict(samples=0), "samples=: 0"),
                        (dict(orient="up"), "'up' is not one of normals|winding"), (dict(foo=1), "unknown option foo"),
                        (dict(samples=1.5), "1.5 is not a whole number")):
        with pytest.raises(bounce.BounceError) as e:
            bounce.solve(CORNELL, **bad, **kw)
        assert needle in str(e.value), str(e.value)
    s = bounce.Scene.load(CORNELL, **kw)
    with pytest.raises(bounce.BounceError, match="option of the scene and F"):
        bounce.solve(s, no_contacts=True)
    # images: the gather's filter off and fewer rays make a different (noisier) K2E; a bad one names itself
    sm = dict(size=(24, 24), spp=1)
    r1, r2 = a.render(**sm), a.render(gather_filter=0, gather_samples=4, **sm)
    assert np.abs(r1["K2E"] - r2["K2E"]).max() > 0 and np.array_equal(r1["E"], r2["E"])
    assert np.array_equal(a.render(**sm)["K2E"], r1["K2E"])   # options not given are reset
    with pytest.raises(bounce.BounceError, match="gather_filter=: 99 is outside"):
        a.render(gather_filter=99, **sm)
    with pytest.raises(bounce.BounceError, match="unknown option gather_rays"):
        a.render(gather_rays=4, **sm)
    with pytest.raises(bounce.BounceError, match=r"up: \(0, 1\) is not"):
        a.render(up=(0, 1), **sm)
    # the bake: flat gives each patch its own vertices (3 per triangle, more than the shared mesh)
    p1, p2 = str(tmp_path / "shared.ply"), str(tmp_path / "flat.ply")
    a.bake(p1, gather=False)
    a.bake(p2, gather=False, flat=True, bake_vertices=None)
    nv = [int(re.search(rb"element vertex (\d+)", open(p, "rb").read(4096)).group(1)) for p in (p1, p2)]
    assert nv[1] > nv[0], nv
    with pytest.raises(bounce.BounceError, match="flat.*crease"):
        a.bake(p2, flat=True, crease=10)
