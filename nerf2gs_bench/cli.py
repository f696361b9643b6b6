"""ns2gs-bench demo | quick | paper-table | ablation | speed-quality | stability | model-size | raster | field | faults | real |
real-photos | real-captures | real-path-speed | street-level | scale | blocks | render-fps | paper-scale-real

Results (JSON + Markdown + PNG, with the machine) go to benchmarks/results/; trained runs are kept
under benchmarks/runs/ and reused when nothing that matters changed. ``demo`` (what make demo runs)
writes everything under outputs/demo/ instead and leaves the committed results alone.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path
from typing import Literal, Optional

import tyro

from nerf2gs_plugin.cli.common import run_cli
from nerf2gs_bench.real_path_speed import RealPathOptions
from nerf2gs_bench.real_photos import RealPhotosOptions

RESULTS = Path("benchmarks/results")
RUNS = Path("benchmarks/runs")


def ensure_street(data: Optional[Path], runs_root: Path) -> Path:
    """The dataset to bench on: the given one, or the embedded synthetic street (made once)."""
    if data is not None:
        return data
    from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street

    from nerf2gs_plugin.data.synthetic_street import GENERATOR_VERSION, read_generator_version

    path = runs_root / "data" / "street"
    if not (path / "transforms.json").is_file():
        generate_street(SynthStreetConfig(out=path))
    elif read_generator_version(path) != GENERATOR_VERSION:  # written by an older generator: make it again
        print(f"[bench] {path}: synthetic street of generator version {read_generator_version(path)}, "
              f"regenerating with version {GENERATOR_VERSION}")
        generate_street(SynthStreetConfig(out=path, overwrite=True))
    return path


@dataclass
class Quick:
    """10-minute CPU version of the paper table: StreetNeRF, Splatfacto with and without --augment-from."""

    data: Optional[Path] = None
    out: Path = RESULTS
    runs: Path = RUNS
    rerun: bool = False
    """Retrain and re-evaluate every run of the bench even when a finished one with its key exists."""

    def main(self) -> None:
        from nerf2gs_bench.paper import paper_table_plan, run_named_bench

        data = ensure_street(self.data, self.runs)
        plan = paper_table_plan("quick", targets=("splatfacto",))
        run_named_bench("quick", plan, data, self.runs, self.out, "Quick paper table (synthetic street, CPU scale)",
                        compare=[("splatfacto + NeRF views", "splatfacto"), ("splatfacto + NeRF views", "StreetNeRF")],
                        figure_labels=["StreetNeRF", "splatfacto", "splatfacto + NeRF views"], rerun=self.rerun)


@dataclass
class Demo:
    """make demo: the quick table's runs (StreetNeRF, Splatfacto, Splatfacto + NeRF views), all under
    outputs/demo/ with readable names, then where they are and the next commands. Committed results
    are left alone (ns2gs-bench quick regenerates benchmarks/results/quick.*)."""

    data: Optional[Path] = None
    """Dataset; default data/street (the synthetic street, made once)."""
    out: Path = Path("outputs/demo")
    """Where the runs (runs/), their readable links, the table and the charts go."""

    def main(self) -> None:
        from nerf2gs_bench.paper import paper_table_plan, run_named_bench
        from nerf2gs_bench.demo import link_runs, next_steps

        data = self.data
        if data is None:
            from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street

            data = Path("data/street")
            if not (data / "transforms.json").is_file():
                generate_street(SynthStreetConfig(out=data))
        plan = paper_table_plan("quick", targets=("splatfacto",))
        results = run_named_bench("quick", plan, data, self.out / "runs", self.out, "Quick paper table (synthetic street, CPU scale)",
                                  compare=[("splatfacto + NeRF views", "splatfacto"), ("splatfacto + NeRF views", "StreetNeRF")],
                                  figure_labels=["StreetNeRF", "splatfacto", "splatfacto + NeRF views"])
        print(next_steps(link_runs(results, self.out), self.out / "quick.md", data))


@dataclass
class PaperTable:
    """Table 1/S1: StreetNeRF and, per target, baseline / + NeRF views / + NeRF views + enhancer."""

    data: Optional[Path] = None
    scale: Literal["quick", "default"] = "default"
    targets: tuple[str, ...] = ("splatfacto", "scaffold-gs", "2dgs")
    enhancer: bool = True
    enhancer_prior: Optional[Path] = None
    """The enhancer rows use this prior (``ns2gs-enhance pretrain``'s ONNX ``out``) as it is, instead of an
    enhancer trained on the capture's own pairs (chosen on validation views: benchmarks/results/enhancer_prior)."""
    enhancer_fine_tune: bool = False
    """With --enhancer-prior: fine-tune the prior (its ``.pt``) on the capture's pairs first (``train --init``)."""
    confidence: tuple[Literal["visibility", "consistency"], ...] = ()
    """Also a "<target> + NeRF views (<mode> confidence)" row per target and mode, trained with --augment.confidence <mode>."""
    out: Path = RESULTS
    runs: Path = RUNS
    rerun: bool = False
    """Retrain and re-evaluate every run of the bench even when a finished one with its key exists."""

    def main(self) -> None:
        from nerf2gs_bench.paper import paper_table_pairs, paper_table_plan, run_named_bench

        data = ensure_street(self.data, self.runs)
        enh = bench_enhancer(data, self.runs, self.scale, self.enhancer_prior, self.enhancer_fine_tune) if self.enhancer else None
        plan = paper_table_plan(self.scale, self.targets, enh, self.confidence)
        run_named_bench("paper_table", plan, data, self.runs, self.out, f"Paper table, synthetic street ({self.scale} scale)",
                        compare=paper_table_pairs(self.targets, enh is not None, self.confidence), figure_labels=["StreetNeRF", "splatfacto", "splatfacto + NeRF views"], rerun=self.rerun)


@dataclass
class Ablation:
    """Table 2: additional views from Splatfacto itself vs from StreetNeRF; StreetNeRF's own ablations."""

    data: Optional[Path] = None
    scale: Literal["quick", "default"] = "default"
    enhancer: bool = True
    enhancer_prior: Optional[Path] = None
    """The enhancer rows use this prior (``ns2gs-enhance pretrain``'s ONNX ``out``) as it is, instead of an
    enhancer trained on the capture's own pairs (chosen on validation views: benchmarks/results/enhancer_prior)."""
    enhancer_fine_tune: bool = False
    """With --enhancer-prior: fine-tune the prior (its ``.pt``) on the capture's pairs first (``train --init``)."""
    confidence: tuple[Literal["visibility", "consistency"], ...] = ()
    """Also a "splatfacto + views from StreetNeRF (<mode> confidence)" row per mode (--augment.confidence <mode>)."""
    streetnerf_terms: bool = True
    """The rows of StreetNeRF without each of its street terms (five more StreetNeRF trainings)."""
    name: str = "ablation"
    """Results file name under out (another name keeps a partial table from replacing the full one)."""
    out: Path = RESULTS
    runs: Path = RUNS
    rerun: bool = False
    """Retrain and re-evaluate every run of the bench even when a finished one with its key exists."""

    def main(self) -> None:
        from nerf2gs_bench.paper import ABLATION_FAMILIES, ablation_plan, confidence_label, family_label, run_named_bench

        data = ensure_street(self.data, self.runs)
        enh = bench_enhancer(data, self.runs, self.scale, self.enhancer_prior, self.enhancer_fine_tune) if self.enhancer else None
        plan = ablation_plan(self.scale, enh, self.confidence, self.streetnerf_terms)
        t = "splatfacto"
        compare = [(f"{t} + views from {t}", t), (f"{t} + views from StreetNeRF", t)]
        compare += [(f"{t} + views from StreetNeRF{confidence_label(c)}", f"{t} + views from StreetNeRF") for c in self.confidence]
        compare += [(f"{t} + views from StreetNeRF{family_label(v)}", t) for v in ABLATION_FAMILIES]
        compare += [(f"StreetNeRF w/o {f}", "StreetNeRF") for f in ("sky", "ground_reg", "transient_mask", "appearance", "point_depth")
                    if self.streetnerf_terms]
        run_named_bench(self.name, plan, data, self.runs, self.out, f"Ablation, synthetic street ({self.scale} scale)", compare=compare,
                        rerun=self.rerun)


@dataclass
class SpeedQuality:
    """Render FPS (log) and training time against BEV PSNR for every run in the paper-table and
    ablation results, Pareto fronts marked. Reads results; trains nothing."""

    results: Path = RESULTS
    """Where paper_table.json / ablation.json are."""
    sources: tuple[str, ...] = ()
    """Results files to read (default: paper_table and ablation, else quick)."""
    out: Path = RESULTS

    def main(self) -> None:
        from nerf2gs_bench.speed_quality import run

        run(self.results, self.out, self.sources or None)


@dataclass
class Stability:
    """Each method swept to its breaking point: 3 seeds (the unstressed baseline), then per stress
    (pose noise, views kept, transients, mask erosion / dilation / drop, exposure, random init; for "<target>+nerf" also
    the reference's training length) levels mild -> harsh until the first failure (PSNR more than
    3 dB below the seeds, NaN, divergence or an error). Runs already trained are reused."""

    data: Optional[Path] = None
    scale: Literal["quick", "default"] = "quick"
    methods: tuple[str, ...] = ("streetnerf", "splatfacto", "scaffold-gs", "2dgs", "splatfacto+nerf")
    """Registered methods, or <target>+nerf for the target trained with StreetNeRF's views (the
    reference trained on the same stressed data)."""
    stresses: tuple[str, ...] = ()
    """Only these stresses (pose noise, views kept, transients, mask erosion / dilation / drop, exposure, init,
    reference steps); default all."""
    seeds: int = 3
    """Unstressed runs per method (the baseline the 3 dB rule is measured against)."""
    steps_fraction: float = 1.0
    """Train every run for this fraction of the scale's steps (schedules rescaled), to fit a CPU budget."""
    out: Path = RESULTS
    runs: Path = RUNS
    rerun: bool = False
    """Retrain and re-evaluate every run of the bench even when a finished one with its key exists."""

    def main(self) -> None:
        from nerf2gs_bench.stability import run, stability_plan

        plan = stability_plan(self.scale, self.methods, stresses=self.stresses or None, steps_fraction=self.steps_fraction,
                              n_seeds=self.seeds)  # bad names fail before any work
        data = ensure_street(self.data, self.runs)
        run(plan, data, self.runs, self.out, self.scale, synthetic=self.data is None, rerun=self.rerun)


@dataclass
class ModelSize:
    """Quality against primitives for each splatting method (densification budget and threshold
    swept); the smallest model within 0.5 dB of the best."""

    data: Optional[Path] = None
    scale: Literal["quick", "default"] = "quick"
    methods: tuple[str, ...] = ("splatfacto", "scaffold-gs", "2dgs")
    augment: bool = False
    """Train every run on StreetNeRF's views (--augment-from)."""
    sweep_fields: Optional[tuple[str, ...]] = None
    """Sweep only these fields (last names, e.g. prune_margin_db prune_weight_fraction) beside the default; all when not given,
    none (the default alone, to hold against an earlier sweep) when given without names."""
    out: Path = RESULTS
    runs: Path = RUNS
    rerun: bool = False
    """Retrain and re-evaluate every run of the bench even when a finished one with its key exists."""

    def main(self) -> None:
        from nerf2gs_bench.size import run, size_plan

        plan = size_plan(self.scale, self.methods, self.augment, self.sweep_fields)  # bad names fail before any work
        data = ensure_street(self.data, self.runs)
        run(plan, data, self.runs, self.out, self.scale, rerun=self.rerun)


def bench_enhancer(data: Path, runs_root: Path, scale: str, prior: Optional[Path] = None, fine_tune: bool = False) -> str:
    """Train (once) the built-in enhancer on this dataset and the bench's StreetNeRF run (trained
    first, or reused: the plan then reuses it too); returns the --augment.enhancer spec. Without
    the reference's own renders the enhancer learns only synthetic degradations, which made real
    bird's-eye renders worse."""
    from nerf2gs_plugin.data import folder_fingerprint
    from nerf2gs_bench.enhancer import bench_prior, ensure_bench_enhancer

    if prior is not None:
        prior = bench_prior(prior, runs_root)
        if not fine_tune:  # the prior as it is: nothing to train on this capture
            return f"onnx:{prior}"
    from nerf2gs_bench.paper import _overrides
    from nerf2gs_bench.runs import RunSpec, train_or_reuse

    dataset = folder_fingerprint(data)
    reference, _ = train_or_reuse(RunSpec("StreetNeRF", "streetnerf", _overrides(scale, "streetnerf")), data, runs_root, dataset)
    return f"onnx:{ensure_bench_enhancer(data, runs_root, scale, reference=reference, init=prior.with_suffix('.pt') if prior else None)}"


@dataclass
class Raster:
    """Rasterizer speed: cpu extension vs torch reference (``raster.*``), or with ``--device cuda``
    gsplat vs the torch reference on the GPU (``raster_cuda.*``)."""

    scale: Literal["quick", "full"] = "quick"
    device: Literal["cpu", "cuda"] = "cpu"
    out: Path = RESULTS

    def main(self) -> None:
        from nerf2gs_bench.raster import run

        run(self.out, self.scale, self.device)


@dataclass
class RenderFps:
    """Splat render speed at a display resolution (1920x1080 by default): forward FPS and one
    forward+backward of 3DGS and 2DGS at several model sizes (``render_fps_<device>.*``)."""

    device: Literal["cpu", "cuda"] = "cpu"
    width: int = 1920
    height: int = 1080
    counts: tuple[int, ...] = (100_000, 500_000, 1_000_000, 3_000_000)
    """3DGS model sizes (primitives)."""
    surfel_counts: tuple[int, ...] = (100_000, 500_000, 1_000_000)
    """2DGS model sizes (primitives)."""
    out: Path = RESULTS

    def main(self) -> None:
        from nerf2gs_bench.render_fps import markdown, run

        print(markdown(run(self.out, self.device, self.width, self.height, self.counts, self.surfel_counts)))


@dataclass
class PaperScaleReal:
    """StreetNeRF's paper preset on a processed real capture within a wall-clock budget, beside the default
    StreetNeRF on the same device (``paper_scale_real_<name>.*``; for a GPU)."""

    data: Path
    """A processed capture (``ns2gs-data process`` output, masks included where made)."""
    budget_s: float = 240.0
    """Wall seconds for the paper preset's training (a probe sets its steps)."""
    device: str = "auto"
    name: Optional[str] = None
    """Results name (default: the capture folder's name)."""
    with_default: bool = True
    """Also train the default (CPU-scale) StreetNeRF on the same device."""
    out: Path = RESULTS
    runs: Path = RUNS

    def main(self) -> None:
        from nerf2gs_bench.paper_scale_real import markdown, run

        print(markdown(run(self.data, self.out, self.runs, self.budget_s, device=self.device, name=self.name,
                           with_default=self.with_default)))


@dataclass
class Field:
    """Hash-grid encoding speed: cpu extension vs torch reference."""

    scale: Literal["quick", "full"] = "quick"
    out: Path = RESULTS

    def main(self) -> None:
        from nerf2gs_bench.field import run

        run(self.out, self.scale)


@dataclass
class Faults:
    """Fault injection: byte flips / truncations of a tiny dataset and run, kill -9 + resume, and the capture path's commands (``faults.*``)."""

    cases: int = 150
    kills: int = 5
    seed: int = 0
    out: Path = RESULTS
    work: Path = RUNS / "faults"
    capture: bool = True
    """Also the capture path (process, masks, enhance apply, eval through their commands; 75 cases, ~15 min on 2 cores)."""

    def main(self) -> None:
        import shutil

        from nerf2gs_bench.faults import run_suite, write_results

        shutil.rmtree(self.work, ignore_errors=True)
        doc = run_suite(self.work, n_files=self.cases, n_kills=self.kills, seed=self.seed)
        if self.capture:
            from nerf2gs_bench.faults_capture import run_capture_suite

            doc["capture"] = run_capture_suite(self.work / "capture", self.seed, log=print)
        js, md = write_results(doc, self.out)
        s = doc["summary"]
        print(f"{s['cases']} cases: {s['clean_errors']} clean errors, {s['finite_ok']} finite, {s['tracebacks']} tracebacks, "
              f"{s['hangs']} hangs, {s['wrong_results']} wrong results -> {js}, {md}")
        if self.capture:
            c = doc["capture"]["summary"]
            print(f"capture path: {c['cases']} cases: {c['ok']} ok, {c['clean_error']} clean errors, {c['traceback']} tracebacks, "
                  f"{c['abort']} native aborts, {c['hang']} hangs, {c['wrong_result']} wrong results")


@dataclass
class Real:
    """The synthetic street as a real capture: a video without poses or masks, through process video ->
    metric scale -> masks (auto) -> StreetNeRF -> Splatfacto +- NeRF views, beside the same frames with
    true poses, scale and masks (``real.*``)."""

    out: Path = RESULTS
    runs: Path = RUNS
    rerun: bool = False
    frames: int = 30
    video_scale: int = 4
    """The video's frames at this multiple of the street's 200x112 (1, 2, 4, 8); the models train at 200x112."""
    reference_steps: int = 1000
    streetnerf_steps: int = 400
    splatfacto_steps: int = 800
    camera_optimizer: Literal["off", "SO3xR3"] = "off"
    """SO3xR3: StreetNeRF refines the estimated training poses (the ground-truth side stays unrefined)."""
    seed: Optional[int] = None
    """Training seed of every run (None: each method's own); the capture and its masks stay the same."""
    street_seed: int = 0
    """The synthetic street's seed (0: the embedded street); another street is another capture."""

    def main(self) -> None:
        from nerf2gs_bench.real import RealBenchOptions, results_md, run_real_bench

        opts = RealBenchOptions(frames=self.frames, video_scale=self.video_scale, reference_steps=self.reference_steps,
                                streetnerf_steps=self.streetnerf_steps, splatfacto_steps=self.splatfacto_steps,
                                camera_optimizer=self.camera_optimizer, seed=self.seed, street_seed=self.street_seed)
        doc = run_real_bench(self.runs, self.out, opts, rerun=self.rerun)
        print(results_md(doc))
        print(f"results: {self.out}/real.md")


@dataclass
class RealPhotos(RealPhotosOptions):
    """A real outdoor photo folder through process images -> masks (auto) -> StreetNeRF -> Splatfacto +- NeRF
    views, scored on held-out photos, with renders from above (``real_photos.*``). The photos stay where they are."""

    out: Path = RESULTS
    runs: Path = RUNS
    rerun: bool = False
    """Retrain and re-evaluate every run of the bench even when a finished one with its key exists."""

    def main(self) -> None:
        from nerf2gs_bench.real_photos import results_md, run_real_photos

        opts = RealPhotosOptions(**{f.name: getattr(self, f.name) for f in fields(RealPhotosOptions)})
        doc = run_real_photos(opts, self.runs, self.out, rerun=self.rerun)
        print(results_md(doc))
        print(f"results: {self.out}/real_photos.md")


@dataclass
class RealCaptures:
    """Public real captures (KITTI, Lund, nuScenes CAM_FRONT, Herz-Jesu-P25; fetched beforehand into --data-root) through
    process -> masks (auto) -> StreetNeRF -> Splatfacto +- NeRF views: held-out PSNR, holes from above,
    stage times (``real_captures.*``)."""

    captures: tuple[str, ...] = ("kitti", "lund", "nuscenes", "herzjesu")
    """Names from nerf2gs_bench.real_captures.CAPTURES."""
    scale: Literal["quick", "full"] = "quick"
    """quick: 40 frames at ~400 px, a few hundred steps per method; full: every frame, the real-photos steps."""
    data_root: Optional[Path] = None
    """Where the fetched frames are (default $NERF2GS_REAL_DATA or ~/.cache/nerf2gs/real)."""
    out: Path = RESULTS
    runs: Path = RUNS
    rerun: bool = False
    docs_picture: Optional[Path] = None
    """Also write one side-by-side frame from above of the first capture whose licence allows it (<= 300 KB PNG)."""
    seeds: tuple[int, ...] = (42,)
    """Seeds of Splatfacto alone and with NeRF views: the deltas are their means (one seed moves a few held-out
    frames by tenths of a dB; the holes from above and the picture are the first seed's)."""

    def main(self) -> None:
        from nerf2gs_bench.real_captures import default_data_root, results_md, run

        doc = run(self.captures, self.data_root or default_data_root(), self.runs, self.out, self.scale, rerun=self.rerun,
                  docs_picture=self.docs_picture, seeds=self.seeds)
        print(results_md(doc))
        print(f"results: {self.out}/real_captures.md")


@dataclass
class RealPathSpeed(RealPathOptions):
    """The real path of a 100-frame 480x360 dashcam stand-in, or of a real capture (--capture kitti), (process -> masks ->
    StreetNeRF -> Splatfacto + NeRF views) timed stage by stage, CPU and wall seconds (``real_path_speed[_CAPTURE].*``)."""

    out: Path = RESULTS
    runs: Path = RUNS

    def main(self) -> None:
        from nerf2gs_bench.real_path_speed import results_md, run, stem

        opts = RealPathOptions(**{f.name: getattr(self, f.name) for f in fields(RealPathOptions)})
        doc = run(self.runs / stem(opts), self.out, opts)
        print(results_md(doc))
        print(f"results: {self.out}/{stem(opts)}.md")


@dataclass
class StreetLevel:
    """What the NeRF's views cost the target at street level on real captures, per region and frame, and
    which ``--augment.*`` lever keeps it (``street_level_lever.*``); reads ``real-captures``' runs."""

    from_runs: Path = RUNS
    """The --runs of an ``ns2gs-bench real-captures`` run (its processed captures and StreetNeRF references)."""
    captures: tuple[str, ...] = ("kitti", "lund")
    variants: tuple[str, ...] = ("default", "composites only", "bev only")
    """Names from nerf2gs_bench.street_level.VARIANTS (the target alone always runs)."""
    steps: int = 700
    """Splatfacto's steps (the real-captures quick scale's)."""
    seeds: tuple[int, ...] = (42, 43)
    """Each variant trained once per seed (one run's street-level PSNR moves by tenths of a dB with the seed)."""
    street: Optional[Path] = None
    """Also a synthetic street (``ns2gs-data synth-street``) at the quick bench's steps: the gain from above kept?"""
    name: str = "street_level_lever"
    """Results' file stem under --out."""
    out: Path = RESULTS
    runs: Path = RUNS

    def main(self) -> None:
        from nerf2gs_bench.street_level import run

        run(self.captures, self.from_runs, self.runs, self.out, self.variants, self.steps, self.seeds, street=self.street, stem=self.name)
        print(f"results: {self.out}/{self.name}.md")


@dataclass
class Scale:
    """How cost grows: time per step, peak memory and model size against images and resolution for
    StreetNeRF and Splatfacto, a fitted law and a 1 km projection, one run vs blocks (``scale.*``)."""

    out: Path = RESULTS
    runs: Path = RUNS
    refit: bool = False
    """Keep the measurements in OUT/scale.json; redo the fits, the projection and the chart."""

    def main(self) -> None:
        from nerf2gs_bench.scale import run

        doc = run(self.out, self.runs, refit=self.refit)
        print(f"results: {self.out}/scale.md ({doc['bench_seconds']:.0f} s)")


@dataclass
class Blocks:
    """City blocks: a street partitioned in 2 blocks, trained, merged, against one whole-scene run, on two streets (``blocks.*``)."""

    out: Path = RESULTS
    runs: Path = RUNS
    steps: int = 200

    def main(self) -> None:
        from nerf2gs_bench.blocks import run

        doc = run(self.out, self.runs, self.steps)
        print(f"results: {self.out}/blocks.md; whole minus merged (dB): {doc['gaps']}")


def main() -> None:
    cmd = tyro.extras.subcommand_cli_from_dict(
        {"demo": Demo, "quick": Quick, "paper-table": PaperTable, "ablation": Ablation, "speed-quality": SpeedQuality,
         "stability": Stability, "model-size": ModelSize, "raster": Raster, "render-fps": RenderFps, "paper-scale-real": PaperScaleReal, "field": Field, "faults": Faults,
         "real": Real, "real-photos": RealPhotos, "real-captures": RealCaptures, "real-path-speed": RealPathSpeed,
         "street-level": StreetLevel, "scale": Scale, "blocks": Blocks},
        description=__doc__,
    )
    cmd.main()


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
