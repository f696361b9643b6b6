"""A/B interleaved in one process: N training views of a StreetNeRF run rendered one after another with torch at 2 threads
(before) vs by two forked processes, 1 thread each (utils/parallel.py); CPU s (with the children's), wall s, max difference.
Usage: python benchmarks/validation/render_workers_ab.py RUN N ROUNDS"""
import argparse, time, resource, torch, multiprocessing as mp
from nerf2gs_plugin.runs.model import load_run_model
ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("run", help="a StreetNeRF run folder")
ap.add_argument("views", type=int, help="training views to render")
ap.add_argument("rounds", type=int, help="interleaved A/B rounds")
args = ap.parse_args()
run = load_run_model(args.run); m = run.model; m.eval()
n = len(run.train_cameras); nv = args.views; reps = args.rounds
cams = [run.train_cameras[i:i+1] for i in range(0, n, n // nv)][:nv]
def cpu():
    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime
def seq():
    return [m.render_camera(c) for c in cams]
def _init():
    torch.set_num_threads(1)
def _job(i):
    with torch.no_grad():
        return m.render_camera(cams[i])
def procs():
    with mp.get_context("fork").Pool(2, initializer=_init) as pool:
        return pool.map(_job, range(len(cams)), chunksize=1)
torch.set_num_threads(2)
with torch.no_grad():
    m.render_camera(cams[0])
    ref = seq()
    res = {"seq": [], "procs": []}
    for rep in range(reps):
        for name, fn in (("seq", seq), ("procs", procs)) if rep % 2 == 0 else (("procs", procs), ("seq", seq)):
            w0, c0 = time.perf_counter(), cpu()
            out = fn()
            w, c = time.perf_counter() - w0, cpu() - c0
            diff = max(float((a[k] - b[k]).abs().max()) for a, b in zip(out, ref) for k in ("rgb", "depth", "accumulation"))
            res[name].append(w)
            print(f"{name}: wall {w:.1f} s, CPU {c:.1f} s, max diff {diff:.2e}, load {open('/proc/loadavg').read().split()[0]}", flush=True)
    print("wall ratio seq/procs per rep:", [round(a / b, 2) for a, b in zip(res["seq"], res["procs"])], "sum:", round(sum(res["seq"]) / sum(res["procs"]), 2))
