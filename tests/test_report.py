"""Tests of harness.report.build_report on a synthetic store: the pages exist,
every <img> and every link resolves on the file system, the metric tables
carry noise floors, and the summary ranks as documented."""

import html.parser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import numpy as np
import pytest

from harness.io import images as imageio
from harness.errors import InputError
from harness.report import build_report
from harness.report import plots
from harness.store import Store

from .synthetic_store import GRIDS, H, MAPPINGS, STEPS, W


class _Collector(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.imgs, self.links, self.ids, self.scripts, self.css = [], [], set(), [], []
        self.text = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            self.ids.add(a["id"])
        if tag == "img":
            self.imgs.append(a.get("src"))
        elif tag == "a" and "href" in a:
            self.links.append(a["href"])
        elif tag == "script" and "src" in a:
            self.scripts.append(a["src"])
        elif tag == "link" and "href" in a:
            self.css.append(a["href"])

    def handle_data(self, data):
        self.text.append(data)


def parse(path):
    c = _Collector()
    c.feed(Path(path).read_text(encoding="utf-8"))
    return c


def all_pages(site):
    return sorted(Path(site).rglob("*.html"))


@pytest.fixture(scope="module")
def synthetic(synthetic_site):
    """(root, store path, run id, build_report's answer), built once per session (conftest)."""
    return synthetic_site


class TestSite:
    def test_pages_exist(self, synthetic):
        root, _, run, info = synthetic
        assert info["index"] == root / "site" / "index.html" and info["index"].is_file()
        assert info["run_id"] == run and set(info["scene_pages"]) == {"slab", "bunny head"}
        for page in info["scene_pages"].values():
            assert page.is_file()
        assert info["n_configs"] == 2 * (len(GRIDS) * len(STEPS) * len(MAPPINGS) + 1) and info["n_failed"] == 2
        assert info["notes"] == []  # FLIP available, nothing skipped
        assert not list(root.glob(".site.*")), "the temporary build folder was left behind"

    def test_every_img_src_exists_and_is_relative(self, synthetic):
        root = synthetic[0]
        n = 0
        for page in all_pages(root / "site"):
            for src in parse(page).imgs:
                assert src and not urlsplit(src).scheme and not src.startswith("/"), src
                target = (page.parent / unquote(src)).resolve()
                assert target.is_file() and target.stat().st_size > 0, f"{page}: {src}"
                n += 1
        assert n > 100

    def test_every_link_resolves(self, synthetic):
        root = synthetic[0]
        site = (root / "site").resolve()
        for page in all_pages(root / "site"):
            p = parse(page)
            for href in p.links + p.scripts + p.css:
                parts = urlsplit(href)
                assert not parts.scheme and not href.startswith("/"), f"{page}: non-relative {href}"
                target = (page.parent / unquote(parts.path)).resolve() if parts.path else page.resolve()
                assert target.is_file(), f"{page}: {href}"
                assert site in target.parents, f"{page}: {href} leaves the site"
                if parts.fragment:
                    assert parts.fragment in parse(target).ids, f"{page}: {href} has no anchor"

    def test_exrs_are_linked_and_readable(self, synthetic):
        root = synthetic[0]
        page = root / "site" / "scenes" / "slab" / "index.html"
        exrs = [h for h in parse(page).links if h.endswith(".exr")]
        assert any(h.startswith("exr/ref_") for h in exrs)
        assert len({h for h in exrs if h.startswith("exr/c")}) == 2 * len(GRIDS) * len(STEPS) * len(MAPPINGS)
        img = imageio.read_exr(page.parent / exrs[-1])
        assert img["rgb"].shape == (H, W, 3)

    def test_tables_have_noise_floors(self, synthetic):
        root = synthetic[0]
        text = (root / "site" / "scenes" / "slab" / "index.html").read_text()
        tables = text.split('<table class="sortable metrics">')[1:]
        assert len(tables) == 2  # subsurface and full
        for t in tables:
            t = t.split("</table>")[0]
            header = t.split("</thead>")[0]
            for m in ("relmse", "si_relmse", "rmse", "energy_ratio", "ssim", "flip", "ciede2000_p95"):
                assert f">{m}</th>" in header
            rows = t.split("<tbody>")[1].count("<tr>")
            assert rows == len(GRIDS) * len(STEPS) * len(MAPPINGS)
            assert t.count('class="floor"') >= rows * 10  # one noise floor beside every value

    def test_index_summary_and_budget(self, synthetic):
        root, store_path, run, info = synthetic
        with Store(store_path) as st:
            confs = [c for c in st.configs(run) if c["status"] == "ok"]
        assert info["budget_rule"] == "median"
        assert info["budget_ms"] == pytest.approx(float(np.median([c["cost_ms"] for c in confs])))
        text = (root / "site" / "index.html").read_text()
        assert "the median cost of the 24 successful configurations" in text
        # The worst-cases table lists the highest subsurface relmse first.
        worst = max(confs, key=lambda c: c["metrics"]["subsurface"]["relmse"]["value"])
        section = text.split("<h2>Worst cases</h2>")[1]
        first_link = section.split('href="')[2].split('"')[0]  # [1] is the scene, [2] the configuration
        assert first_link.endswith(f"#c{worst['id']}")
        # The best under budget is affordable and no affordable one is better.
        for scene in ("slab", "bunny head"):
            cs = [c for c in confs if c["scene"] == scene]
            afford = [c for c in cs if c["cost_ms"] <= info["budget_ms"]]
            best = min(afford, key=lambda c: c["metrics"]["subsurface"]["relmse"]["value"])
            assert f"#c{best['id']}" in text.split("<h2>Worst cases</h2>")[0]

    def test_failed_configs_are_listed(self, synthetic):
        root = synthetic[0]
        text = (root / "site" / "scenes" / "bunny head".replace(" ", "_") / "index.html").read_text()
        assert "GL_OUT_OF_MEMORY &lt;allocating 64^3 grid&gt;" in text  # escaped

    def test_plots_written(self, synthetic):
        root = synthetic[0]
        names = {p.name for p in (root / "site" / "scenes" / "slab" / "plots").iterdir()}
        for tag in ("subsurface_relmse", "subsurface_flip", "full_relmse"):
            for kind in ("vs_steps", "vs_grid", "heatmap", "vs_cost"):
                assert f"{tag}_{kind}.png" in names
        assert "energy_vs_steps.png" in names

    def test_offline_assets_only(self, synthetic):
        root = synthetic[0]
        for f in list((root / "site").rglob("*.html")) + list((root / "site" / "static").glob("*.*s")):
            text = f.read_text()
            assert "http://" not in text and "https://" not in text, f


class TestOptions:
    def test_given_budget_run_and_extra_sections(self, synthetic, tmp_path):
        _, store_path, run, _ = synthetic
        info = build_report(store_path, tmp_path / "s", run_id=run, cost_budget_ms=0.5, title="Nightly <x>",
                            extra_sections=[{"title": "Trend", "html": "<p id='trend'>ok</p>"},
                                            {"title": "Plain", "text": "a < b"}], flip_maps=False)
        text = info["index"].read_text()
        assert info["budget_ms"] == 0.5 and info["budget_rule"] == "given"
        assert "Nightly &lt;x&gt;" in text and "<p id='trend'>ok</p>" in text and "a &lt; b" in text
        assert "none within 0.5 ms" in text  # every config costs more; the cheapest is shown
        scene = (tmp_path / "s" / "scenes" / "slab" / "index.html").read_text()
        assert "FLIP maps are not shown" in scene and "_flip.png" not in scene

    def test_rebuild_replaces_site(self, synthetic, tmp_path):
        _, store_path, _, _ = synthetic
        out = tmp_path / "s"
        build_report(store_path, out, flip_maps=False)
        (out / "stale.html").write_text("old")
        build_report(store_path, out, flip_maps=False)
        assert not (out / "stale.html").exists() and (out / "index.html").is_file()

    def test_never_replaces_a_foreign_folder(self, synthetic, tmp_path):
        _, store_path, _, _ = synthetic
        out = tmp_path / "mine"
        out.mkdir()
        (out / "notes.txt").write_text("precious")
        with pytest.raises(InputError, match="non-empty folder that the harness did not write"):
            build_report(store_path, out, flip_maps=False)
        assert (out / "notes.txt").read_text() == "precious"

    def test_missing_store_and_run(self, synthetic, tmp_path):
        _, store_path, _, _ = synthetic
        with pytest.raises(InputError, match="does not exist"):
            build_report(tmp_path / "nope.sqlite", tmp_path / "s")
        assert not (tmp_path / "nope.sqlite").exists()
        with pytest.raises(InputError, match="run 999 does not exist"):
            build_report(store_path, tmp_path / "s", run_id=999)
        assert not (tmp_path / "s").exists()

    def test_missing_images_are_noted_not_fatal(self, tmp_path):
        store_path = tmp_path / "r.sqlite"
        with Store(store_path) as st:
            run = st.start_run("sweep", {})
            st.record_config(run, "ghost", "h", {"grid": 8, "steps": 8}, "ok",
                             metrics=[{"image": "subsurface", "metric": "relmse", "value": 0.5, "noise_floor": 0.1}],
                             timings={"total": 1.0}, render_dir=tmp_path / "gone", reference_dir=tmp_path / "gone2")
        info = build_report(store_path, tmp_path / "site")
        text = info["scene_pages"]["ghost"].read_text()
        assert "does not exist" in text
        assert "plots over them are left out" not in text  # 'grid' works as the grid key too
        for src in parse(info["scene_pages"]["ghost"]).imgs:
            assert (info["scene_pages"]["ghost"].parent / src).is_file()


class TestPlots:
    def test_pareto_front(self):
        pts = [(1, 5), (2, 3), (3, 4), (4, 1), (2, 2.5), (5, 1)]
        assert [pts[i] for i in plots.pareto_front(pts)] == [(1, 5), (2, 2.5), (4, 1)]

    @pytest.mark.parametrize("gk", ["N", "grid"])
    def test_facets_split_on_non_axis_params(self, gk):
        cs = [{"params": {gk: g, "steps": s, "mapping": m, "skip": 2}}
              for g in (16, 32) for s in (8, 16) for m in ("a", "b")]
        assert list(plots.facets(cs)) == ["mapping=a", "mapping=b"]
        assert plots.varying_params(cs) == [gk, "steps", "mapping"]
        assert plots.grid_key(cs) == gk

    def test_optimal_scale_prefers_si_relmse(self):
        c = {"metrics": {"subsurface": {"si_relmse": {"value": 0.1, "params": {"scales": [2.0, 3.0, 4.0]}},
                                        "energy_ratio": {"value": 0.5, "params": {}}}}}
        assert plots.optimal_scale(c) == pytest.approx(3.0)
        del c["metrics"]["subsurface"]["si_relmse"]
        assert plots.optimal_scale(c) == pytest.approx(2.0)
