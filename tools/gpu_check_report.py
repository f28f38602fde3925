#!/usr/bin/env python3
"""tools/gpu-check's report: the raw folder's logs and JSON files into one
gpu-check.json and one markdown table (gpu-check.md), each figure beside the
target it is judged against (issue 32). Standard library only: it runs on the
bare GPU machine."""
import json
import os
import re
import statistics
import sys

raw, out, total_s = sys.argv[1], sys.argv[2], float(sys.argv[3])


def load(name):
    p = os.path.join(raw, name)
    try:
        with open(p) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def log(name):
    try:
        with open(os.path.join(raw, name + ".log"), errors="replace") as f:
            return f.read()
    except OSError:
        return ""


meta = load("meta.json") or {}
doc = {"meta": meta, "total_s": total_s, "steps": {}, "figures": []}
for f in sorted(os.listdir(raw)):
    if f.endswith(".rc.json"):
        r = load(f)
        doc["steps"][r["name"]] = r
rows = []


def figure(what, value, unit, target=None, ok=None, note=""):
    doc["figures"].append({"what": what, "value": value, "unit": unit, "target": target, "ok": ok, "note": note})
    v = "–" if value is None else (f"{value:.3g}" if isinstance(value, float) else str(value))
    verdict = "" if ok is None else (" ✓" if ok else " ✗")
    rows.append(f"| {what} | {v} {unit} | {target or ''}{verdict} | {note} |")


def status(name):
    s = doc["steps"].get(name)
    if s is None:
        return "not run"
    return "timed out" if s["rc"] in (124, 137) else (f"failed (rc {s['rc']})" if s["rc"] else "")


def parts(name):
    """The "GPU parts" rows of a bench step log: {part: ms}."""
    rows, on = {}, False
    for line in log(name).splitlines():
        if line.startswith("GPU parts on"):
            on = True
        elif on:
            m = re.match(r"^  (\S.*?)\s+(-?[\d.]+)$", line)
            if m:
                rows[m.group(1)] = float(m.group(2))
            elif line.strip():
                on = False
    return rows


# Golden numerics on the GPU engine.
m = re.findall(r"(\d+) passed, (\d+) failed", log("golden"))
if m:
    p, f = map(int, m[-1])
    figure("golden files, GPU engine", f"{p} passed, {f} failed", "", "all within the CPU tolerances", f == 0)
else:
    figure("golden files, GPU engine", None, "", "all within the CPU tolerances", False, status("golden"))

# One step on guitar and playbot; the CPU engine on this machine beside it where it ran.
targets = {("guitar", 256): 10.0, ("guitar", 512): 30.0}
for scene in ("guitar", "playbot"):
    for name in sorted((n for n in doc["steps"] if n.startswith(scene + "_")), key=lambda n: int(n.split("_")[1])):
        res = int(name.split("_")[1])
        j = load(name + ".json")
        if not j:
            figure(f"{scene} step at {res} px", None, "ms", None, False, status(name))
            continue
        gpu = next((r for r in j["runs"] if r["label"] == "gpu"), None)
        cpu = next((r for r in j["runs"] if r["label"] == "cpu"), None)
        t = targets.get((scene, res))
        if gpu:
            med = lambda r, k: r.get(k) if r.get(k) is not None else None
            fmt = lambda v: "–" if v is None else f"{v:.2f}"
            col, geo = med(gpu, "colour_step_median_ms"), med(gpu, "geometry_step_median_ms")
            # Judged on the geometry step's median (90% of the schedule), else the mean.
            judged = geo if geo is not None else gpu["ms_per_step"]
            note = f"{gpu['device']}; medians: colour {fmt(col)} ms, geometry {fmt(geo)} ms; mean {gpu['ms_per_step']:.2f} ms over {gpu['steps']} steps"
            # The host's share (absent before 2026-11-28's second session): its pairing and its waits on the device.
            if gpu.get("geometry_pairing_median_ms") is not None or gpu.get("colour_pairing_median_ms") is not None:
                note += (f"; host pairing colour {fmt(med(gpu, 'colour_pairing_median_ms'))} / geometry "
                         f"{fmt(med(gpu, 'geometry_pairing_median_ms'))} ms, waiting on the device "
                         f"{fmt(med(gpu, 'colour_device_wait_median_ms'))} / {fmt(med(gpu, 'geometry_device_wait_median_ms'))} ms")
            # Recording and submitting the step's commands (absent before 2026-11-29).
            if gpu.get("geometry_record_median_ms") is not None:
                note += (f"; recording colour {fmt(med(gpu, 'colour_record_median_ms'))} / geometry "
                         f"{fmt(med(gpu, 'geometry_record_median_ms'))} ms, submitting "
                         f"{fmt(med(gpu, 'colour_submit_median_ms'))} / {fmt(med(gpu, 'geometry_submit_median_ms'))} ms, "
                         f"{med(gpu, 'geometry_bind_groups') or 0:.0f} bind groups made a geometry step")
            # The compute passes they ran in (absent before 2026-11-30's third session).
            if gpu.get("geometry_passes") is not None:
                note += f" in {med(gpu, 'geometry_passes'):.0f} compute passes"
            if cpu:
                note += f"; CPU engine {cpu['ms_per_step']:.1f} ms a step on {meta.get('cores', '?')} cores (mean), CPU/GPU {cpu['ms_per_step'] / max(gpu['ms_per_step'], 1e-9):.3g}x"
            figure(f"{scene} step at {res} px", judged, "ms", t and f"≤ {t:.0f} ms", t and judged <= t, note)
            if scene == "playbot":
                mib = gpu.get("gpu_memory_mib")
                figure(f"playbot GPU memory at {res} px", mib, "MiB", "≤ 2048 MiB" if res == 512 else None,
                       (mib is not None and mib <= 2048) if res == 512 else None,
                       f"engine allocations over the run (before 2026-11-30: after its load only); process peak resident {j['peak_resident_mib']:.0f} MiB")

def with_without(step, what, short, extra=lambda j: ""):
    """A term's cost: the step time of `gast bench step --compare-*` with the term on against off."""
    j = load(f"{step}.json")
    if j and len(j["runs"]) == 2:
        a, b = j["runs"]
        figure(f"{what}, step time with / without", b["ms_per_step"] / max(a["ms_per_step"], 1e-9), "×",
               None, None, f"{a['ms_per_step']:.2f} ms without, {b['ms_per_step']:.2f} ms with{extra(j)}")
    elif j and len(j["runs"]) > 2:
        # More arms than one (`--compare-relief`: the relief, then the relief and the leak),
        # each against the first, with its phases' medians.
        a, ms = j["runs"][0], lambda v: "–" if v is None else f"{v:.2f}"
        for b in j["runs"][1:]:
            phases = ", ".join(f"{p} {ms(b.get(f'{p}_step_median_ms'))} / {ms(a.get(f'{p}_step_median_ms'))} ms"
                               for p in ("colour", "geometry"))
            figure(f"{b['label']}, step time with / without", b["ms_per_step"] / max(a["ms_per_step"], 1e-9), "×",
                   None, None, f"{a['ms_per_step']:.2f} ms without, {b['ms_per_step']:.2f} ms with; medians with / "
                   f"without: {phases}{extra(j)}")
    else:
        figure(f"{short}, with / without", None, "×", None, False, status(step))


# The assignment terms' host round trip.
with_without("compare_assign", "assignment terms (λ_asc 10 + λ_as 0.015)", "assignment terms")
# The palette hold's kernels (λ_pal 100 with the object focus).
with_without("compare_palette", "palette hold (λ_pal 100)", "palette hold")
# The depth relief (8 px) and the phase leak beside it: both geometry options, on the GPU since
# 2026-11-30.
with_without("compare_relief", "depth relief", "depth relief",
             lambda j: f"; guitar × block2 at {j['resolution']} px")
# The relief and the leak against the CPU engine on this machine: the first step's losses.
m = re.search(r"first step's losses, relative difference: total (\S+), GCFM (\S+), content (\S+), TV (\S+), depth (\S+)",
              log("relief_check"))
if m:
    total, gcfm, content, tv, depth = (float(x) for x in m.groups())
    figure("depth relief 8 px + phase leak, GPU against the CPU engine: first step's GCFM, relative difference", gcfm, "",
           "≤ 1e-3", gcfm <= 1e-3, f"total {total:.1e} (the assignment terms' draws differ between engines), content "
           f"{content:.1e}, TV {tv:.1e}, depth {depth:.1e}; guitar × wave")
else:
    figure("depth relief 8 px + phase leak, GPU against the CPU engine", None, "", "≤ 1e-3", False, status("relief_check"))
# The host pairing itself (`gast bench pairing`): in blocks (since 2026-11-30) and in one block,
# Jonker–Volgenant's start against the plain paths.
j = load("pairing.json")
if j:
    blocks = ""
    if j.get("one_block_pairing_ms") is not None:
        blocks = (f"; {j['blocks_median']:.0f} blocks of ≤ {j['assign_block']} rows (one block: {j['one_block_pairing_ms']:.2f} ms, "
                  f"assignment {j['one_block_assign_ms']:.2f}); mean pair cost {j['pair_cost']:.4f} against "
                  f"{j['one_block_pair_cost']:.4f} in one block, {j['drawn_pair_cost']:.4f} as drawn")
    figure(f"host pairing at {j['resolution']} px (guitar × wave, {j['threads']} threads)", j["pairing_ms"], "ms", None, None,
           f"median of {j['draws']} draws, {j['rows_median']:.0f} rows: cost matrix {j['cost_ms']:.2f}, assignment "
           f"{j['assign_ms']:.2f} (one block: the plain shortest paths {j['plain_ms']:.2f}, ratio {j['assign_over_plain']:.3f}), "
           f"pulls {j['pull_ms']:.2f} ms{blocks}")
else:
    figure("host pairing", None, "ms", None, False, status("pairing"))
# The depth's sliced Wasserstein term (the frame recipe), at the largest step size.
with_without("compare_sliced_depth", "λ_swd 1 (frame recipe)", "λ_swd 1",
             lambda j: f", whole frame at {j['resolution']} px")

# The full schedule, load to export.
for name, what, target in (("full_guitar", "full schedule, guitar × block2", 60.0), ("full_fern", "full schedule, fern × block2", 180.0)):
    s = doc["steps"].get(name)
    if s is None:
        if name == "full_fern":
            figure(what, None, "s", f"≤ {target:.0f} s", None,
                   "not run (not asked for, or no fitted fern in .gpu-check: GAST_FERN_SCENE at prepare)")
        continue
    rep = load(os.path.join(name, "report.json"))
    note = status(name)
    if rep:
        steps = rep.get("steps") or []
        note = (note + "; " if note else "") + f"{len(steps)} steps at {rep.get('config', {}).get('resolution', '?')} px"
        # An object run's RGB distance on the object (report.json's summary.on_object, since 2026-12-01).
        obj = (rep.get("summary") or {}).get("on_object")
        if obj:
            note += f"; RGB NN-cos on the object {obj['nn_distance_matched']:.4f} -> {obj['nn_distance_after']:.4f}"
    figure(what + " (load to export)", s["wall_s"] if s["rc"] == 0 else None, "s", f"≤ {target:.0f} s",
           s["rc"] == 0 and s["wall_s"] <= target, note)

# fern's schedule extrapolated from its first five cycles (the step time is flat).
rep = load(os.path.join("fern_500", "report.json"))
if rep and rep.get("steps"):
    n = len(rep["steps"])
    prep = sum(t for _, t in rep.get("stages_s", []))
    # What follows the steps (scenes, previews and their measures, the sheet); absent before 2026-11-28.
    after = sum(t for _, t in rep.get("outputs_s", []))
    per = rep["optimisation_s"] / n
    full = prep + per * 3000 + after
    figure("full schedule, fern × block2, from 500 steps (prepare + 3,000 × step + outputs)", full, "s", "≤ 180 s",
           full <= 180,
           f"{per * 1000:.1f} ms a step over {n} steps at {rep.get('config', {}).get('resolution', '?')} px, "
           f"prepare {prep:.1f} s, outputs {after:.1f} s "
           f"({', '.join(f'{k} {t:.1f} s' for k, t in rep.get('outputs_s', [])) or 'not timed by this build'})")
elif "fern_500" in doc["steps"]:
    figure("full schedule, fern × block2, from 500 steps", None, "s", "≤ 180 s", False, status("fern_500"))

# One fern step on its LLFF cameras at the reference's scale, and where it goes (the GPU parts).
j = load("fern_parts.json")
fern_gpu = next((r for r in (j or {"runs": []})["runs"] if r["label"] == "gpu"), None)
doc["fern_parts"] = parts("fern_parts") if fern_gpu else {}
if fern_gpu:
    fmt = lambda k: "–" if fern_gpu.get(k) is None else f"{fern_gpu[k]:.2f}"
    judged = fern_gpu.get("geometry_step_median_ms") or fern_gpu["ms_per_step"]
    figure(f"fern step at {j.get('resolution', '?')} px on the longer side (its LLFF cameras, frame recipe)", judged,
           "ms", "≤ 57 ms (what 3,000 steps in 3 min leave)", judged <= 57.0,
           f"medians: colour {fmt('colour_step_median_ms')} ms, geometry {fmt('geometry_step_median_ms')} ms; "
           f"the GPU parts in the table below")
elif "fern_parts" in doc["steps"]:
    figure("fern step (its LLFF cameras)", None, "ms", "≤ 57 ms", False, status("fern_parts"))

# fern at 504×378 with each style asked for (fern504_STYLE): the run's time and its measures.
for name in sorted(n for n in doc["steps"] if n.startswith("fern504_")):
    rep = load(os.path.join(name, "report.json"))
    sm = (rep or {}).get("summary") or {}
    note = status(name)
    if sm:
        note = (note + "; " if note else "") + (
            f"{len(rep.get('steps') or [])} steps, {rep['optimisation_s']:.0f} s optimising; "
            f"RGB NN-cos {sm['nn_distance_matched']:.4f} -> {sm['nn_distance_after']:.4f}, "
            f"depth SW {sm['depth_style_matched']['sw']:.3f} -> {sm['depth_style_after']['sw']:.3f}, "
            f"depth changed {100 * sm['inverse_depth_change']:.1f}%, collapse {'yes' if sm.get('colour_collapse') else 'no'}")
    s = doc["steps"][name]
    figure(f"fern × {name[len('fern504_'):]} at 504×378 (load to export)", s["wall_s"] if s["rc"] == 0 else None, "s",
           None, None, note)

# A baseline build against this one (ab_RES_ARMROUND steps): step medians and each GPU part.
def median(xs):
    return statistics.median(xs) if xs else None


base_rev = ""
try:
    with open(os.path.join(raw, "baseline.txt")) as f:
        base_rev = f.read().strip()
except OSError:
    pass


def compare(prefix, arms, title, names):
    """Two arms alternated (PREFIX_RES_ARMROUND steps): the step medians' ratio, second arm over
    first, one figure per phase, and each GPU part's medians and ratio (returned)."""
    out = []
    for res in sorted({int(n.split("_")[1]) for n in doc["steps"] if n.startswith(prefix + "_")}):
        got = {}
        for arm in arms:
            steps = sorted(n for n in doc["steps"] if n.startswith(f"{prefix}_{res}_{arm}"))
            runs = [next((r for r in (load(n + ".json") or {"runs": []})["runs"] if r["label"] == "gpu"), None)
                    for n in steps]
            got[arm] = {"runs": [r for r in runs if r], "parts": [parts(n) for n in steps],
                        "status": [status(n) for n in steps]}
        b, n = got[arms[0]], got[arms[1]]
        for key, what in (("colour_step_median_ms", "colour"), ("geometry_step_median_ms", "geometry")):
            bv = median([r[key] for r in b["runs"] if r.get(key) is not None])
            nv = median([r[key] for r in n["runs"] if r.get(key) is not None])
            rounds = lambda a: ", ".join(f"{r[key]:.2f}" for r in a["runs"] if r.get(key) is not None)
            figure(f"guitar {what} step at {res} px, {title}", None if not (bv and nv) else nv / bv, "×",
                   None, None, f"{names[0]}: {rounds(b)} ms; {names[1]}: {rounds(n)} ms"
                   + ("" if bv and nv else "".join(f"; {x}" for x in b["status"] + n["status"] if x)))
        for part in (b["parts"][0] if b["parts"] else {}):
            bv = median([p[part] for p in b["parts"] if part in p])
            nv = median([p[part] for p in n["parts"] if part in p])
            if bv is not None and nv is not None:
                out.append({"resolution": res, "part": part, "baseline_ms": bv, "new_ms": nv,
                            "ratio": nv / bv if bv > 0 else None})
    return out


ab_parts = compare("ab", ("base", "new"), "this build / baseline", (f"baseline {base_rev or '(--base)'}", "this build"))
# A compute pass per dispatch against runs of dispatches sharing one (pass_RES_ARMROUND, this build alone).
compare("pass", ("each", "shared"), "shared passes / a pass per dispatch", ("GAST_GPU_PASSES=each", "shared"))
# Bind groups made every step against kept from step to step (bind_RES_ARMROUND, this build alone).
compare("bind", ("off", "on"), "kept bind groups / made every step", ("GAST_BIND_CACHE=0", "kept"))
# VGG on the object's window against the whole frame (win_RES_ARMROUND, this build alone).
compare("win", ("off", "on"), "VGG window / whole frame", ("GAST_VGG_WINDOW=0", "window"))
# The assignment pairing in blocks of 256 rows against one block of up to 512 (blk_RES_ARMROUND).
compare("blk", ("one", "two"), "pairing in blocks of 256 / one block", ("--assign-block 512", "--assign-block 256"))
tile_parts = compare("tile", ("t64", "auto"), "GEMM tiles auto / 64²", ("GAST_GEMM_TILE=64", "auto"))
doc["tile_parts"] = tile_parts
# Every product in 128² blocks (arm t128, not in the dry run): whether auto's threshold is right.
wide_parts = compare("tile", ("t64", "t128"), "GEMM tiles 128² / 64²", ("GAST_GEMM_TILE=64", "GAST_GEMM_TILE=128"))
doc["wide_parts"] = wide_parts
doc["ab_parts"] = ab_parts

# The CPU engine on 1, 2, 4, ... threads (cpu_threads_T): its step and the speed-up over one thread.
scaling = []
for name in sorted((n for n in doc["steps"] if n.startswith("cpu_threads_")), key=lambda n: int(n.split("_")[2])):
    t = int(name.split("_")[2])
    j = load(name + ".json")
    cpu = next((r for r in (j or {"runs": []})["runs"] if r["label"] == "cpu"), None)
    if not cpu:
        figure(f"CPU engine, guitar step on {t} thread{'s' if t > 1 else ''}", None, "ms", None, None, status(name))
        continue
    scaling.append({"threads": t, "ms_per_step": cpu["ms_per_step"], "colour_ms": cpu.get("colour_step_median_ms"),
                    "geometry_ms": cpu.get("geometry_step_median_ms")})
    one = scaling[0]["ms_per_step"] if scaling[0]["threads"] == 1 else None
    fmt = lambda v: "–" if v is None else f"{v:.1f}"
    figure(f"CPU engine, guitar step at {j.get('resolution', '?')} px on {t} thread{'s' if t > 1 else ''}",
           cpu["ms_per_step"], "ms", None, None,
           (f"{one / cpu['ms_per_step']:.2f}x one thread's step; " if one else "")
           + f"medians: colour {fmt(scaling[-1]['colour_ms'])} ms, geometry {fmt(scaling[-1]['geometry_ms'])} ms; "
           f"mean over {cpu['steps']} steps")
doc["cpu_threads"] = scaling

# The depth network.
d = log("depth_net")
lines = [l.strip() for l in d.splitlines() if "GPU" in l or "gpu" in l]
figure("Depth Anything V2 Small on the GPU engine", None if not lines else lines[-1][:160], "", None, None, status("depth_net"))

# The studio.
shot = os.path.join(out, "studio.png")
adapter = re.findall(r"studio: headless on (.+)", log("studio"))
ran = re.findall(r"scripted run paused after (\d+) steps", log("studio"))
# The run's state kept against a crash at its pause (the optimiser's moments read back from the GPU).
kept = re.findall(r"kept the run's state at step (\d+): ([0-9.]+) s", log("studio"))
figure("studio drawn headless on the GPU (gast studio --headless)", "screenshot" if os.path.exists(shot) else None, "",
       None, None, "; ".join(x for x in (status("studio"), adapter[-1] if adapter else "",
                                         f"a {ran[-1]}-step run" if ran else "",
                                         f"its state kept at step {kept[0][0]} in {float(kept[0][1]) * 1e3:.0f} ms"
                                         if kept else "") if x))

with open(os.path.join(out, "gpu-check.json"), "w") as f:
    json.dump(doc, f, indent=2)
md = [f"# gpu-check, {meta.get('date', '?')}", "",
      f"Card: {meta.get('card') or 'no nvidia-smi (not an NVIDIA machine)'}; {meta.get('cores', '?')} CPU cores; "
      f"dry run: {'yes (reduced sizes)' if meta.get('dry_run') else 'no'}; {total_s:.0f} s in all.", "",
      "| what | measured | target | notes |", "|---|---|---|---|", *rows, ""]
if doc["fern_parts"]:
    md += ["GPU parts of a fern step (VGG and GCFM at the step's side squared; the raster on a fern camera):", "",
           "| part | ms |", "|---|---|", *(f"| {k} | {v:.3f} |" for k, v in doc["fern_parts"].items()), ""]
if ab_parts:
    md += [f"GPU parts, this build against the baseline ({base_rev or '--base'}), medians of the rounds:", "",
           "| px | part | baseline ms | this build ms | ratio |", "|---|---|---|---|---|",
           *(f"| {p['resolution']} | {p['part']} | {p['baseline_ms']:.3f} | {p['new_ms']:.3f} | "
             f"{'–' if p['ratio'] is None else format(p['ratio'], '.3g')} |" for p in ab_parts), ""]
if tile_parts:
    wide = {(p["resolution"], p["part"]): p for p in wide_parts}
    ratio = lambda p: "–" if p is None or p["ratio"] is None else format(p["ratio"], ".3g")
    ms = lambda p: "–" if p is None else f"{p['new_ms']:.3f}"
    md += ["GPU parts with the GEMM's 64² tiles, auto (128² for the large products) and 128² for every "
           "product, this build, medians of the rounds:", "",
           "| px | part | 64² ms | auto ms | auto / 64² | 128² ms | 128² / 64² |", "|---|---|---|---|---|---|---|",
           *(f"| {p['resolution']} | {p['part']} | {p['baseline_ms']:.3f} | {p['new_ms']:.3f} | {ratio(p)} | "
             f"{ms(wide.get((p['resolution'], p['part'])))} | {ratio(wide.get((p['resolution'], p['part'])))} |"
             for p in tile_parts), ""]
with open(os.path.join(out, "gpu-check.md"), "w") as f:
    f.write("\n".join(md))
print("\n".join(md))
