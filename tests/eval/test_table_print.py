"""A table printed into a pipe is complete: every column, no cell cut with an ellipsis."""

from __future__ import annotations

import io

from rich.table import Table

from nerf2gs_plugin.eval.table_print import print_table


def _wide_table() -> Table:
    table = Table(title="Quick paper table (synthetic street, CPU scale)")
    cols = ["method", "PSNR street", "PSNR bev_1", "PSNR bev_2", "SSIM street", "SSIM bev_1", "SSIM bev_2",
            "LPIPS bev_1", "road PSNR bev_1", "road PSNR bev_2", "FPS", "primitives", "train s"]
    for c in cols:
        table.add_column(c)
    table.add_row("Splatfacto + NeRF views + enhancer", *[f"{20 + i:.2f}" for i in range(len(cols) - 1)])
    return table


def test_piped_table_is_complete():
    out = io.StringIO()  # not a terminal, like `make demo | tee log`
    print_table(_wide_table(), file=out)
    text = out.getvalue()
    assert "…" not in text
    assert "Splatfacto + NeRF views + enhancer" in text
    for c in ("road PSNR bev_2", "LPIPS bev_1", "train s", "31.00"):
        assert c in text


def test_rich_default_would_cut_it():  # what the test above guards against
    from rich.console import Console

    out = io.StringIO()
    Console(file=out).print(_wide_table())
    assert "…" in out.getvalue() or "train s" not in out.getvalue()


def test_eval_summary_reports_a_nerf_in_parameters_not_primitives(capsys):
    from nerf2gs_plugin.cli.eval import print_table as eval_table
    from nerf2gs_plugin.methods.splatfacto.model import SplatfactoModel
    from nerf2gs_plugin.methods.streetnerf.model import StreetNeRFModel

    assert StreetNeRFModel.primitive_kind is None and SplatfactoModel.primitive_kind == "Gaussians"
    res = {"method_name": "streetnerf", "step": 9, "fps": 0.5, "train_seconds": 3.0,
           "results": {"street": {"psnr": 25.0, "ssim": 0.8, "lpips": 0.1, "fps": 0.5, "num_images": 7}},
           "size": {"primitives": 786432, "primitive_kind": None, "parameters": 1_600_000, "megabytes": 6.1}}
    eval_table(res)
    out = capsys.readouterr().out
    assert "primitives" not in out and "1,600,000 parameters" in out and "6.10 MB" in out
    res["size"].update(primitive_kind="Gaussians", primitives=12251)
    eval_table(res)
    assert "12,251 Gaussians" in capsys.readouterr().out
