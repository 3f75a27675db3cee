"""``hollowtree view``: the level of detail, the data routes, the refused paths, the command's
errors, and the page in a real headless Chromium (skipped, saying why, without one)."""

from __future__ import annotations

import http.client
import json
import os
import shutil
import subprocess
import sys
import threading

import numpy as np
import pytest

import hollowtree
from hollowtree.classes import CLASS_NAMES, ClassId
from hollowtree.pipeline import view
from hollowtree.pipeline.view_lod import (
    FIRST_POINTS,
    LEVELS,
    first_view,
    level_rows,
    level_size,
    pack,
    unpack,
)
from hollowtree.tiling.store import RunStore


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> str:
    """A small labelled store: the Wazir Khan mosque, 120 k points, 8 tiles, with its tree (the element check off: the tests are about the viewer, not which
    domes a learned check keeps on a 120 k toy scan)."""
    from hollowtree.pipeline.run import run_workflow
    from hollowtree.pipeline.workflow import load_workflow
    from hollowtree.scenes.synth import synth

    d = tmp_path_factory.mktemp("view")
    synth("wazir_khan", d / "wk.laz", n_points=120_000, seed=5)
    (d / "wf.yaml").write_text(f"""\
input: {{files: [{d / 'wk.laz'}]}}
store: {d / 's.zarr'}
ingest: {{tile_size: 50.0}}
coarse: {{min_support: 300}}
tree: {{enabled: true, max_depth: 2, verify: false}}
cluster: {{scheduler: sync}}
""")
    run_workflow(load_workflow(d / "wf.yaml"), progress=False, say=lambda _: None)
    return str(d / "s.zarr")


@pytest.fixture(scope="module")
def server(store):
    srv = view.make_server(store, port=0)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    yield srv
    srv.shutdown()
    srv.server_close()


def _get(srv, path: str, method: str = "GET", host: str | None = None) -> tuple[int, bytes]:
    conn = http.client.HTTPConnection(*srv.server_address[:2], timeout=30)
    conn.putrequest(method, path, skip_host=host is not None, skip_accept_encoding=True)  # the path as given
    if host is not None:
        conn.putheader("Host", host)
    conn.endheaders()
    r = conn.getresponse()
    body = r.read()
    conn.close()
    return r.status, body


# ---------------------------------------------------------------------- level of detail (pure)
def test_levels_partition_a_node():
    n = 10_000
    rows = [level_rows(n, k, seed=7) for k in range(LEVELS)]
    every = np.concatenate(rows)
    assert len(every) == n
    assert len(np.unique(every)) == n
    assert [len(r) for r in rows] == [level_size(n, k) for k in range(LEVELS)]
    assert len(rows[0]) == int(np.ceil(n / 2 ** (LEVELS - 1)))
    np.testing.assert_array_equal(level_rows(n, 3, seed=7, first=1), np.sort(np.concatenate(rows[1:4])))
    np.testing.assert_array_equal(level_rows(n, 2, seed=7), rows[2])  # seeded: the same every time


def test_first_view_is_bounded_whatever_the_store_size():
    for n_tiles in (1, 10, 1000):
        nodes = [{"tile": t, "chunk": c, "rows": 262_144} for t in range(n_tiles) for c in range(8)]
        plan = first_view(nodes)
        assert len({p["tile"] for p in plan}) <= 6
        assert sum(np.ceil(262_144 * 2.0 ** (p["level"] - LEVELS + 1)) for p in plan) <= FIRST_POINTS


def test_the_viewer_agrees_with_the_pipeline_constants():
    """view_store copies three constants so that the server starts without the pipeline."""
    from hollowtree.pipeline import labels
    from hollowtree.pipeline.export import CLASS_COLOURS
    from hollowtree.pipeline.view_store import CLASS_RGB, LABELS_STAGE, LEAF_BITS

    assert LEAF_BITS == labels.LEAF_BITS
    assert LABELS_STAGE == labels.STAGE
    assert [tuple(int(round(255 * v)) for v in c) for c in CLASS_COLOURS] == list(CLASS_RGB)


def test_pack_round_trip():
    a = {"p": np.arange(12, dtype=np.float32).reshape(4, 3), "c": np.array([1, 2, 3], np.uint8),
         "i": np.array([7, 8], np.uint32)}
    head, back = unpack(pack({"n": 4}, a))
    assert head["n"] == 4
    assert [f["offset"] % 4 for f in head["fields"]] == [0, 0, 0]
    for k in a:
        np.testing.assert_array_equal(back[k], a[k])


# ---------------------------------------------------------------------- the data routes
def test_nodes_carry_the_store_labels(server, store):
    """Every level of every node together: each kept core point once, with its own labels."""
    v = server.view
    rs = RunStore.open(store)
    lab = {k: rs.read_slice(f"labels/{k}") for k in ("class", "instance", "segment")}
    assert v.rows == {t: rs.array_length(f"tiles/{t}/index") for t in v.tiles}  # from the ingest records
    got, want = np.zeros(len(CLASS_NAMES), np.int64), np.zeros(len(CLASS_NAMES), np.int64)
    for t in v.tiles:
        d = rs.read_unit(f"tiles/{t}", ["index", "core", "xyz"])
        idx = d["index"][d["core"]].astype(np.int64)
        want += np.bincount(lab["class"][idx], minlength=len(CLASS_NAMES))
        world = {int(i): xyz for i, xyz in zip(idx, d["xyz"][d["core"]] * v.scale + v.offset, strict=True)}
        for nd in (n for n in v.nodes if n["tile"] == t):
            head, a = unpack(v.node(t, nd["chunk"], LEVELS - 1, 0))
            got += np.bincount(a["class"], minlength=len(CLASS_NAMES))
            # a point's labels are those of the input point at its position
            pos = a["position"].astype(np.float64) + v.origin
            by_pos = {tuple(np.round(w, 3)): i for i, w in world.items()}
            for k in range(0, head["n"], 97):
                i = by_pos[tuple(np.round(pos[k], 3))]
                assert a["class"][k] == lab["class"][i]
                assert a["instance"][k] == lab["instance"][i]
                assert (int(a["segment"][k]) << 20 | int(a["leaf"][k])) == int(lab["segment"][i])
    np.testing.assert_array_equal(got, want)


def test_meta_counts_are_the_store_counts(server, store):
    status, body = _get(server, "/api/meta")
    meta = json.loads(body)
    assert status == 200
    counts = {c["name"]: c["count"] for c in meta["classes"] if c["count"]}
    assert counts == hollowtree.open(store).counts()
    assert meta["first_view"]
    assert meta["nodes"]


def test_element_and_tree_routes(server, store):
    scan = hollowtree.open(store)
    dome = np.flatnonzero(scan.class_id == ClassId.DOME)
    i = int(dome[0])
    seg = int(scan.segment[i])
    status, body = _get(server, f"/api/element?instance={scan.instance[i]}&segment={seg >> 20}&leaf={seg & 0xFFFFF}")
    el = json.loads(body)
    assert status == 200
    assert el["n_points"] == int((scan.instance == scan.instance[i]).sum())
    assert el["path"]
    assert el["path"][0]["sequence"] == "root"
    assert el["path"][-1]["node"] == seg & 0xFFFFF
    roots = json.loads(_get(server, "/api/tree")[1])
    assert roots["total"] == len(roots["roots"]) > 0
    r = roots["roots"][0]
    sub = json.loads(_get(server, f"/api/subtree?tree={r['tree']}&node={r['node']}")[1])
    assert r["tree"] in sub["segments"]
    assert r["node"] in sub["nodes"]
    assert "children" in json.loads(_get(server, f"/api/children?tree={r['tree']}&node={r['node']}")[1])


@pytest.mark.parametrize("path", ["/../zarr.json", "/%2e%2e/zarr.json", "/viewer.js/../../zarr.json", "/zarr.json",
                                  "/api/../zarr.json", "/..%2f..%2fetc/passwd", "//etc/passwd", "/view_static/viewer.js",
                                  "/tiles/0/xyz/c/0/0", "/index.html?x=/../zarr.json", "/api/meta/../../zarr.json"])
def test_paths_outside_the_routes_are_refused(server, path):
    status, body = _get(server, path)
    assert status == 404, (path, status)
    assert b"zarr_format" not in body
    assert b"root:" not in body


def test_bad_requests_and_writes_are_refused(server):
    assert _get(server, "/api/node?tile=0&chunk=0&level=99")[0] == 400
    assert _get(server, "/api/node?tile=x&chunk=0&level=0")[0] == 400
    assert _get(server, "/api/node?tile=123456&chunk=0&level=0")[0] == 400
    assert _get(server, "/api/meta", method="POST")[0] == 405
    assert _get(server, "/api/meta", method="DELETE")[0] == 405
    assert _get(server, "/api/meta", host="evil.example:8765")[0] == 403  # DNS rebinding
    assert _get(server, "/api/meta", host="localhost:8765")[0] == 200
    status, body = _get(server, "/")
    assert status == 200
    assert b"viewer.js" in body
    assert server.server_address[0] == "127.0.0.1"


# ---------------------------------------------------------------------- the command's errors
def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hollowtree", "view", *args], capture_output=True, text=True,
                          timeout=60)


def test_bad_store_is_one_line_and_exit_2(tmp_path):
    proc = _cli(str(tmp_path / "missing.zarr"))
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "does not exist" in proc.stderr
    RunStore.create(tmp_path / "bare.zarr", attrs={"ingest": {"tiles": []}})
    proc = _cli(str(tmp_path / "bare.zarr"))
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "no complete labels" in proc.stderr


# ---------------------------------------------------------------------- the page in Chromium
def _chromium() -> str | None:
    for name in (os.environ.get("HOLLOWTREE_CHROMIUM"), "chromium", "chromium-browser", "google-chrome"):
        if name and (path := shutil.which(name)):
            return path
    return None


@pytest.fixture(scope="module")
def page(server):
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install .[dev])")
    exe = _chromium()
    if exe is None:
        pytest.skip("no chromium executable (apt-get install chromium, or set HOLLOWTREE_CHROMIUM)")
    messages: list[str] = []
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=exe, args=[
            "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox"])
        pg = browser.new_page(viewport={"width": 1280, "height": 800})
        pg.on("console", lambda m: messages.append(f"{m.type}: {m.text}") if m.type in ("error", "warning") else None)
        pg.on("pageerror", lambda e: messages.append(f"pageerror: {e}"))
        pg.on("requestfailed", lambda r: messages.append(f"request failed: {r.url}"))
        pg.goto(f"http://127.0.0.1:{server.server_address[1]}/")
        pg.wait_for_function("window.hollowtreeViewer && window.hollowtreeViewer.ready", timeout=30_000)
        pg.wait_for_function("!window.hollowtreeViewer.busy()", timeout=30_000)
        yield pg, messages
        browser.close()


def test_page_draws_the_scan_without_errors(page, tmp_path):
    pg, messages = page
    assert messages == []
    assert pg.evaluate("window.hollowtreeViewer.errors") == []
    assert pg.evaluate("window.hollowtreeViewer.loadedCount()") > 10_000
    pg.evaluate("window.hollowtreeViewer.redraw()")
    shot = tmp_path / "view.png"
    pg.locator("canvas").screenshot(path=str(shot))
    from PIL import Image

    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    background = np.abs(img - np.array([21, 23, 27])).sum(axis=-1) <= 12
    assert background.mean() < 0.5, f"{background.mean():.0%} of the canvas is background"


def test_legend_counts_are_the_store_counts(page, store):
    pg, _ = page
    rows = pg.eval_on_selector_all("#legend tbody tr", "rs => rs.map(r => [r.children[1].textContent, r.children[2].textContent])")
    shown = {name: int(n.replace(",", "")) for name, n in rows}
    assert shown == hollowtree.open(store).counts()


def test_a_class_toggle_changes_the_drawn_count(page):
    pg, _ = page
    before = pg.evaluate("window.hollowtreeViewer.drawnCount()")
    pg.locator(f'#legend input[data-cls="{int(ClassId.GROUND)}"]').uncheck()
    after = pg.evaluate("window.hollowtreeViewer.drawnCount()")
    ground = pg.evaluate(f"window.hollowtreeViewer.batches.reduce((s, b) => s + b.cls.filter(c => c === {int(ClassId.GROUND)}).length, 0)")
    pg.locator(f'#legend input[data-cls="{int(ClassId.GROUND)}"]').check()
    assert 0 < after < before
    assert before - after == ground
    assert pg.evaluate("window.hollowtreeViewer.drawnCount()") == before


def test_clicking_a_dome_point_shows_its_element_and_tree_path(page, store):
    pg, _ = page
    scan = hollowtree.open(store)
    index, xyz = scan.points()
    cls = scan.class_id[index]
    from scipy.spatial import cKDTree

    dome = np.flatnonzero(cls == ClassId.DOME)
    # points inside a dome's surface (every point within 0.5 m is dome), highest first: in
    # front of everything from above
    near = cKDTree(xyz).query_ball_point(xyz[dome], 0.5)
    dome = dome[[bool((cls[n] == ClassId.DOME).all()) for n in near]]
    dome = dome[np.argsort(-xyz[dome, 2], kind="stable")][:3000]
    screen = np.asarray(pg.evaluate("ps => ps.map(p => window.hollowtreeViewer.project(p[0], p[1], p[2]))",
                                    xyz[dome].tolist()))
    box = pg.locator("canvas").bounding_box()
    inside = ((screen[:, 0] > box["x"] + 20) & (screen[:, 0] < box["x"] + box["width"] - 20)
              & (screen[:, 1] > box["y"] + 20) & (screen[:, 1] < box["y"] + box["height"] - 20))
    assert inside.any(), "no dome point in view"
    x, y = screen[np.argmax(inside)]  # the highest dome point in view
    pg.mouse.click(x, y)
    pg.wait_for_function("window.hollowtreeViewer.lastPick !== undefined", timeout=10_000)
    pg.wait_for_function("!window.hollowtreeViewer.lastPick || window.hollowtreeViewer.lastPick.path", timeout=10_000)
    pick = pg.evaluate("window.hollowtreeViewer.lastPick")
    assert pick, pg.inner_text("#element")
    assert pick["class"] == "dome"
    assert pick["instance"] > 0
    assert pick["n_points"] == int((scan.instance == pick["instance"]).sum())
    assert pick["path"]
    assert pick["path"][0]["sequence"] == "root"
    text = pg.inner_text("#element")
    assert "dome" in text
    assert "root to leaf" in text


def test_every_colour_mode_draws(page):
    pg, messages = page
    shots = {}
    for mode in ("instance", "segment", "score", "rgb", "intensity", "class"):
        pg.select_option("#mode", mode)
        pg.evaluate("window.hollowtreeViewer.redraw()")
        shots[mode] = pg.locator("canvas").screenshot()
    assert len(set(shots.values())) == len(shots)  # each mode colours differently
    assert messages == []


def test_a_tree_node_in_the_outline_highlights_its_points(page):
    pg, _ = page
    pg.wait_for_selector("#tree li")
    key = pg.get_attribute("#tree > li", "data-key")
    tree, node = (int(k) for k in key.split("/"))
    sub = pg.evaluate(f"fetch('/api/subtree?tree={tree}&node={node}').then(r => r.json())")
    pg.keyboard.press("Escape")  # no highlight left by an earlier test's pick: wait for this node's
    pg.click("#tree > li > .lab")
    pg.wait_for_selector("#tree > li > .lab.on", timeout=10_000)
    pg.wait_for_function("window.hollowtreeViewer.highlightedCount() > 0", timeout=10_000)
    want = pg.evaluate("""s => window.hollowtreeViewer.batches.reduce((n, b) => {
        for (let i = 0; i < b.n; i++) if (s.segments.includes(b.segment[i]) && s.nodes.includes(b.leaf[i])) n++;
        return n; }, 0)""", sub)
    assert pg.evaluate("window.hollowtreeViewer.highlightedCount()") == want
    pg.keyboard.press("Escape")
    assert pg.evaluate("window.hollowtreeViewer.highlightedCount()") == 0


def test_a_store_on_s3_gives_the_same_view(server, store, monkeypatch):
    """The same store on S3 (a moto server): the same counts, nodes and tree paths."""
    pytest.importorskip("moto", reason="moto[server] is a dev dependency")
    s3fs = pytest.importorskip("s3fs", reason="s3fs is a dev dependency")
    from moto_s3 import moto_server

    from hollowtree.pipeline.view_store import ViewStore

    with moto_server() as env:
        for k, v in env.items():
            monkeypatch.setenv(k, v)
        fs = s3fs.S3FileSystem(key="test", secret="test", endpoint_url=env["AWS_ENDPOINT_URL"])
        fs.mkdir("hollowtree-view")
        fs.put(store.rstrip("/") + "/", "hollowtree-view/s.zarr", recursive=True)
        remote = ViewStore("s3://hollowtree-view/s.zarr")
        local = server.view
        assert remote.counts.tolist() == local.counts.tolist()
        assert remote.nodes == local.nodes
        nd = local.nodes[-1]
        _, a = unpack(remote.node(nd["tile"], nd["chunk"], 2, 0))
        _, b = unpack(local.node(nd["tile"], nd["chunk"], 2, 0))
        for k in b:
            np.testing.assert_array_equal(a[k], b[k])
        roots, _ = remote.tree().roots(5)
        assert roots == local.tree().roots(5)[0]
