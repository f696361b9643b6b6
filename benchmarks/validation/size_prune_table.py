"""Collect the JSONs of ``size_prune.py`` into one table per scene and method, with the 0.5 dB band
of issue 20 computed on the validation views (mean of val_street and val_bev PSNR).

Usage: python benchmarks/validation/size_prune_table.py OUT_STEM DIR
Produced benchmarks/results/size_prune.{json,md} from the size branch's runs (quick scale, 800 steps,
one thread; the swept configurations are those of ``ns2gs-bench model-size --scale quick``).
"""
import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from nerf2gs_bench.machine import machine_line  # noqa: E402
from nerf2gs_plugin.utils.io import atomic_write_text  # noqa: E402

BAND_DB = 0.5
TARGET_RATIO = 1.5
SWEPT = ("default", "cap2000", "cap8000", "thresh0.0016")  # the model-size sweep's configurations
NOTES = {"w0.05d": "F=0.05 at every refinement during densification (tried, removed)"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out_stem", type=Path)
    ap.add_argument("dir", type=Path)
    args = ap.parse_args()
    out_stem, folder = args.out_stem, args.dir
    groups: dict[tuple[str, str], dict[str, dict]] = {}
    for f in sorted(folder.glob("*.json")):
        r = json.loads(f.read_text())
        groups.setdefault((Path(r["data"]).name, r["method"]), {})[r["label"]] = {
            "primitives": r["primitives"], "megabytes": r["megabytes"], "fps": r["fps"], "mean_psnr": r["mean_psnr"],
            "val_street": r["psnr"]["val_street"], "val_bev": r["psnr"]["val_bev"], "overrides": r["overrides"]}
    doc = {"machine": machine_line(), "band_db": BAND_DB, "target_ratio": TARGET_RATIO, "scenes": {}}
    lines = ["# Blend-weight prune against the size sweep, on the validation views", "",
             f"Machine: {doc['machine']}", "",
             "Quick scale (800 steps, one thread, two benches beside: FPS noisy). PSNR on val_street / val_bev, mean of the "
             f"two; the band is {BAND_DB} dB below the best swept configuration ({', '.join(SWEPT)}); `w<F>` is "
             "`--pipeline.model.strategy.prune-weight-fraction F` on the default configuration.", ""]
    for (scene, method), rows in sorted(groups.items()):
        swept = {k: v for k, v in rows.items() if k in SWEPT}
        best = max(swept, key=lambda k: swept[k]["mean_psnr"])
        band = [k for k, v in swept.items() if v["mean_psnr"] >= swept[best]["mean_psnr"] - BAND_DB]
        smallest = min(band, key=lambda k: swept[k]["primitives"])
        checks = {}
        for label, v in rows.items():
            if label.startswith("w"):
                checks[label] = {"within_band": v["mean_psnr"] >= swept[best]["mean_psnr"] - BAND_DB,
                                 "over_smallest": v["primitives"] / swept[smallest]["primitives"],
                                 "below_best_db": swept[best]["mean_psnr"] - v["mean_psnr"]}
        doc["scenes"].setdefault(scene, {})[method] = {"rows": rows, "best": best, "smallest_within_0_5dB": smallest,
                                                        "default_over_smallest": rows["default"]["primitives"] / swept[smallest]["primitives"],
                                                        "prune": checks}
        lines += [f"## {scene}, {method}", "", "| run | primitives | MB | mean PSNR | val_street | val_bev | FPS | note |",
                  "|---|---|---|---|---|---|---|---|"]
        for label, v in sorted(rows.items(), key=lambda kv: kv[1]["primitives"]):
            note = []
            if label == best:
                note.append("best")
            if label == smallest:
                note.append("smallest within 0.5 dB")
            if label in checks:
                c = checks[label]
                note.append(f"{c['over_smallest']:.2f}x the smallest, {c['below_best_db']:.2f} dB below the best"
                            + ("" if c["within_band"] else " (OUT of the band)"))
            if label in NOTES:
                note.append(NOTES[label])
            fps = f"{v['fps']:.0f}" if v["fps"] else "n/a"
            lines.append(f"| {label} | {v['primitives']} | {v['megabytes']:.1f} | {v['mean_psnr']:.2f} | {v['val_street']:.2f} | "
                         f"{v['val_bev']:.2f} | {fps} | {'; '.join(note)} |")
        lines.append("")
    atomic_write_text(out_stem.with_suffix(".json"), json.dumps(doc, indent=1))
    atomic_write_text(out_stem.with_suffix(".md"), "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
