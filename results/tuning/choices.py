#!/usr/bin/env python3
"""Writes results/tuning/choices.json: the effect of each recipe choice that was measured, and
the spreads they are read against, computed from the committed results files it names.

Run from the repository root: python3 results/tuning/choices.py

Every value is copied from the named file at full precision; an effect is the variant's score
minus the reference's, a spread the largest minus the smallest score of runs that differ only
in the student's (or the upsampler's) seed. Nothing is rounded here: docs/tuning.md prints
these values at two decimals, so a difference printed there can differ in its last digit from
the difference of two rounded scores printed elsewhere.
"""

import csv
import json
import os
import sys

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
OUT = os.path.join(ROOT, "results", "tuning", "choices.json")
SPLITS = ("val", "novel", "voice")
EVAL_LOG = "eval_{}.log"  # nldf eval's output, where a folder kept no metrics JSON
SHARP = "{}_metrics.json"  # how results/sharp names its nldf eval files


def read_json(rel):
    with open(os.path.join(ROOT, rel)) as f:
        return json.load(f)


def models(rel):
    if rel.endswith(".log"):
        # nldf eval's log: its last JSON line is the metrics (the models of the split).
        with open(os.path.join(ROOT, rel)) as f:
            lines = [line for line in f if line.startswith("[{")]
        if not lines:
            sys.exit(f"{rel}: no metrics line")
        return json.loads(lines[-1])
    d = read_json(rel)
    return d["models"] if isinstance(d, dict) else d


def model(rel, label):
    for m in models(rel):
        if m.get("label") == label:
            return m
    sys.exit(f"{rel}: no model labelled {label!r}")


def run(folder, label, what, splits=SPLITS, pattern="metrics_{}.json"):
    """A model's scores on each split, from FOLDER/metrics_<split>.json (or PATTERN)."""
    files = [f"{folder}/{pattern.format(s)}" for s in splits]
    out = {"what": what, "files": "; ".join(files), "label": label}
    for key, name in (("head_psnr", "head_psnr"), ("mouth_psnr", "mouth_psnr"), ("repainted_pct", "repainted")):
        out[key] = {}
        for s in splits:
            v = model(f"{folder}/{pattern.format(s)}", label).get(name)
            if v is not None:
                out[key][s] = v * 100 if key == "repainted_pct" else v
    return out


def view(folder, label, name):
    """A model's head PSNR on one view of the novel split."""
    for v in model(f"{folder}/metrics_novel.json", label)["by_view"]:
        if v["view"] == name:
            return v["head_psnr"]
    sys.exit(f"{folder}: no view {name!r}")


def scores_csv(rel, label):
    """A row of a posed ablation's scores.csv (whole-frame PSNR per split)."""
    with open(os.path.join(ROOT, rel)) as f:
        for row in csv.DictReader(f):
            if row["label"] == label:
                return {
                    "what": f"{rel}, label {label}",
                    "files": rel,
                    "label": label,
                    "psnr": {s: float(row[f"{s}_psnr"]) for s in SPLITS},
                }
    sys.exit(f"{rel}: no row {label!r}")


def frontier(rel, model_name, precision, runtime, key="head_psnr"):
    for p in read_json(rel)["points"]:
        if p["model"] == model_name and p["precision"] == precision and p["runtime"] == runtime:
            return {
                "what": f"{model_name}, {precision} {runtime}",
                "files": rel,
                key: {s["split"]: s[key] for s in p["scores"]},
                "ms_2_threads": p["ms_2_threads"],
            }
    sys.exit(f"{rel}: no point {model_name!r} {precision} {runtime}")


def diff(a, b, key):
    """b minus a on every split both have."""
    return {s: b[key][s] - a[key][s] for s in SPLITS if s in a.get(key, {}) and s in b.get(key, {})}


SPREADS = {}


def spread(sid, scene, kind, runs, note, key="head_psnr"):
    values = {s: [r[key][s] for r in runs if s in r[key]] for s in SPLITS}
    entry = {
        "id": sid,
        "scene": scene,
        "scene_kind": kind,
        "metric": key,
        "runs": runs,
        "spread": {s: max(v) - min(v) for s, v in values.items() if len(v) > 1},
        "note": note,
    }
    if key == "head_psnr" and all("mouth_psnr" in r for r in runs):
        mouth = {s: [r["mouth_psnr"][s] for r in runs] for s in SPLITS}
        entry["mouth_spread"] = {s: max(v) - min(v) for s, v in mouth.items()}
    SPREADS[sid] = entry
    return entry


def verdict(effect, spread_id):
    """Per split, whether the effect lies inside the spread; and a summary."""
    if spread_id is None:
        return {}, "no spread measured"
    sp = SPREADS[spread_id]["spread"]
    per = {s: ("inside" if abs(e) <= sp[s] else "outside") for s, e in effect.items() if s in sp}
    outside = [s for s, v in per.items() if v == "outside"]
    if not outside:
        return per, "no difference"
    if len(outside) == len(per) == len(SPLITS):
        return per, "outside the spread on every split"
    if len(outside) == len(per):
        return per, "outside the spread on " + " and ".join(outside)
    return per, "outside the spread on " + " and ".join(outside) + " only"


EFFECTS = []


def effect(eid, choice, scene, kind, reference, variant, spread_id, note, key="head_psnr"):
    e = diff(reference, variant, key)
    per, summary = verdict(e, spread_id)
    entry = {
        "id": eid,
        "choice": choice,
        "scene": scene,
        "scene_kind": kind,
        "metric": key,
        "reference": reference,
        "variant": variant,
        "effect": e,
        "spread_id": spread_id,
        "verdict": per,
        "summary": summary,
        "note": note,
    }
    if key == "head_psnr":
        for k, out in (("mouth_psnr", "mouth_effect"), ("repainted_pct", "repainted_effect_points")):
            d = diff(reference, variant, k)
            if d:
                entry[out] = d
        ms = SPREADS.get(spread_id, {}).get("mouth_spread")
        if ms and "mouth_effect" in entry:
            entry["mouth_verdict"] = {
                s: ("inside" if abs(v) <= ms[s] else "outside") for s, v in entry["mouth_effect"].items()
            }
    EFFECTS.append(entry)
    return entry


def main():
    S7 = "results/demo/tune_s7"
    H2S7 = "results/demo/tune_h2s7"
    S0 = "results/demo/xeon_s0"
    KEPT = "results/demo/kept_audio"
    POOL_NOTE = (
        "the demo's own run held a beam pool of 81920 rays, students trained from a config file "
        "40960 (docs/demo.md, 'One run, several seeds'), so this difference mixes the setting "
        "with the pool size"
    )

    # --- spreads -------------------------------------------------------------------------
    s7_student = run(S7, "student", "seed 7: the recipe of the time, student seed 0 (the demo's own run, pool 81920)")
    s7_init1 = run(f"{S7}/init1", "init1", "seed 7: the same recipe, student seed 1 (from its config file, pool 40960)")
    spread(
        "s7_seed", "standard head, seed 7", "tuning", [s7_student, s7_init1],
        "two student seeds from one teacher, audio encoder fine-tuned (the recipe of the time); "
        "the two runs also differ in pool size (81920 against 40960), so this is the seed and "
        "the pool together",
    )
    s0_kept0 = run(f"{S0}/audio_fixed_seed0", "s0fa0", "seed 0: audio encoder kept, student seed 0")
    s0_kept1 = run(f"{S0}/audio_fixed_seed1", "s0fa1", "seed 0: audio encoder kept, student seed 1")
    spread("s0_kept_seeds", "standard head, seed 0", "test", [s0_kept0, s0_kept1],
           "the demo's recipe (encoder kept, pool 40960), student seeds 0 and 1, one teacher")
    s1_kept0 = run(f"{KEPT}/xeon_s1", "student", "seed 1: the demo's recipe, student seed 0")
    s1_kept1 = run(f"{KEPT}/xeon_s1/student_seed1", "s1seed1", "seed 1: the demo's recipe, student seed 1")
    spread("s1_kept_seeds", "standard head, seed 1", "test", [s1_kept0, s1_kept1],
           "the demo's recipe (encoder kept, pool 40960), student seeds 0 and 1, one teacher")
    h2_kept0 = run(f"{KEPT}/xeon_head2", "student", "second head: the demo's recipe, student seed 0")
    h2_kept1 = run(f"{KEPT}/xeon_head2/student_seed1", "h2seed1", "second head: the demo's recipe, student seed 1")
    spread("h2_kept_seeds", "second head, seed 0", "test", [h2_kept0, h2_kept1],
           "the demo's recipe (encoder kept, pool 40960), student seeds 0 and 1, one teacher")
    s0_tuned = [
        run(f"{S0}/pool_2048", "s0pool", "seed 0: encoder fine-tuned, pool 40960, student seed 0"),
        run(f"{S0}/student_seed1", "s0init1", "seed 0: encoder fine-tuned, pool 40960, student seed 1"),
        run(f"{S0}/student_seed2", "s0init2", "seed 0: encoder fine-tuned, pool 40960, student seed 2"),
    ]
    spread("s0_tuned_seeds", "standard head, seed 0", "test", s0_tuned,
           "the recipe before the encoder was kept (fine-tuned, pool 40960), student seeds 0, 1 and 2, one teacher")
    up = "results/sharp/xeon_512/second_init"
    spread(
        "u512_init", "standard head, seed 0 at 512", "test",
        [run(up, "upsampler", "the upsampler, first draw", SPLITS, SHARP),
         run(up, "upsampler_again", "the upsampler, second draw", SPLITS, SHARP)],
        "two initial draws of the upsampler over one student (20 frames of each split)",
    )

    # --- teacher -------------------------------------------------------------------------
    effect(
        "teacher_steps", "teacher: 1100 steps pinned, held 60 % then decayed", "standard head, seed 0", "test",
        run(f"{KEPT}/xeon_s0", "teacher", "the demo's teacher: 1100 steps pinned"),
        run("results/distill/xeon/before", "teacher", "the former 5-minute teacher"),
        None, "one teacher seed each; no teacher seed spread was measured",
    )
    effect(
        "teacher_bounds", "teacher: samples only inside the head's bounds", "standard head, seed 0", "test",
        frontier(f"{KEPT}/xeon_s0/frontier/frontier.json", "teacher 6x128 (32 samples/ray)", "fp32", "candle"),
        frontier(f"{KEPT}/xeon_s0/frontier/frontier.json",
                 "teacher 6x128 (32 samples/ray), no skipping, no early stop", "fp32", "candle"),
        None, "the same trained teacher rendered without skipping the space outside its bounds (val only)",
    )

    # --- student network -----------------------------------------------------------------
    fr = "results/frontier/epyc_256/frontier.json"
    rt = frontier(fr, "student 16x128 (K = 8), pixels only", "fp32", "ort", "psnr")
    for eid, name in (("preset_28x256", "student 28x256, pixels only"),
                      ("preset_28x128", "student 28x128, pixels only"),
                      ("preset_16x128_k16", "student 16x128, pixels only")):
        effect(eid, "student network: the real-time preset (16 x 128, K = 8)", "standard head, seed 0", "test",
               rt, frontier(fr, name, "fp32", "ort", "psnr"), None,
               "pixels-only students, 8.5 minutes each after a 5-minute teacher; whole-frame PSNR", key="psnr")
    for eid, sc, ba, now, lab in (
        ("anchor_s0", "standard head, seed 0", "results/demo/before_anchor/xeon_s0", S0, "student"),
        ("anchor_s1", "standard head, seed 1", "results/demo/before_anchor/xeon_s1", "results/demo/xeon_s1", "student"),
        ("anchor_h2", "second head, seed 0", "results/demo/before_anchor/xeon_head2", "results/demo/xeon_head2", "student"),
    ):
        ref = run(now, lab, "anchored beams (encoder fine-tuned, pool 81920)")
        var = run(ba, lab, "before anchoring (encoder fine-tuned)")
        ref["farther_head_psnr"] = view(now, lab, "farther")
        var["farther_head_psnr"] = view(ba, lab, "farther")
        e = effect(eid, "student: anchored beams", sc, "test", ref, var,
                   "s0_tuned_seeds" if eid == "anchor_s0" else None,
                   "both headline demo runs of their time; the first seed-1 run stopped at its cap at step 4432")
        e["farther_effect"] = var["farther_head_psnr"] - ref["farther_head_psnr"]
    before = run("results/distill/xeon/before", "student",
                 "the posed recipe cut to 15 minutes: no opacity, batch 4096, 2000 pseudo views, every recorded pixel")
    after = run("results/demo/before_anchor/xeon_s0", "student",
                "the demo's recipe of the time: opacity, batch 2048, 600 pseudo views, 4096 pixels a frame")
    effect("demo_recipe_bundle", "student: the demo's recipe as a whole (opacity, batch, views, steps)",
           "standard head, seed 0", "test", after, before, None,
           "many settings changed together, and the teachers differ (1100 pinned steps against 5 minutes)")

    # --- student training on the tuning scenes ----------------------------------------------
    for eid, folder, label, choice in (
        ("s7_mix50", S7, "mix50", "student: pseudo_fraction 0.75"),
        ("s7_mix90", S7, "mix90", "student: pseudo_fraction 0.75"),
        ("s7_lam0", S7, "lam0", "student: lambda 0.2"),
        ("s7_s6000", f"{S7}/s6000", "s6000", "student: 4500 steps"),
        ("s7_pv2400", f"{S7}/pv2400", "pv2400", "student: 600 pseudo views"),
        ("s7_lr1e3", f"{S7}/lr1e3", "lr1e3", "student: learning rate 5e-4"),
        ("s7_lr2e3", f"{S7}/lr2e3", "lr2e3", "student: learning rate 5e-4"),
        ("s7_ema", f"{S7}/ema", "ema", "student: no weight averaging"),
    ):
        effect(eid, choice, "standard head, seed 7", "tuning", s7_student,
               run(folder, label, f"seed 7: {label}"), "s7_seed", POOL_NOTE)
    effect("s7_audio", "student: audio_lr_scale 0 (the teacher's audio encoder kept)", "standard head, seed 7",
           "tuning", run(f"{S7}/audio_fixed", "fa7", "seed 7: encoder kept (from its config file, pool 40960)"),
           s7_student, "s7_seed", POOL_NOTE)
    h2_student = run(H2S7, "student", "second head, seed 7: the recipe of the time (the demo's own run, pool 81920)")
    effect("h2s7_floor05", "student: opacity_floor 0", "second head, seed 7", "tuning", h2_student,
           run(H2S7, "floor05", "second head, seed 7: opacity_floor 0.05"), None, POOL_NOTE)
    h2_lr = run(f"{H2S7}/lr1e3", "h2lr", "second head, seed 7: learning rate 1e-3")
    effect("h2s7_lr1e3", "student: learning rate 5e-4", "second head, seed 7", "tuning", h2_student, h2_lr,
           None, POOL_NOTE)
    effect("h2s7_lr1e3_floor05", "student: opacity_floor 0", "second head, seed 7", "tuning", h2_lr,
           run(f"{H2S7}/lr1e3_floor05", "h2lrf", "second head, seed 7: 1e-3 with opacity_floor 0.05"), None,
           "both from config files (pool 40960), at learning rate 1e-3")

    # --- student training: checks and choices on the test scenes ------------------------------
    s0_head = run(S0, "student", "seed 0: the headline student of the time (encoder fine-tuned, pool 81920)")
    effect("s0_lr1e3", "student: learning rate 5e-4", "standard head, seed 0", "test", s0_head,
           run("results/demo/lr1e3_s0", "student", "seed 0: nldf demo with the student at 1e-3 (pool 81920)"),
           "s0_tuned_seeds", "both demo runs of the time (encoder fine-tuned, pool 81920), one teacher")
    effect("s0_ema", "student: no weight averaging", "standard head, seed 0", "test", s0_tuned[0],
           run(f"{S0}/ema", "s0ema", "seed 0: weights averaged at 0.998 (pool 40960)"), "s0_tuned_seeds",
           "both from config files (encoder fine-tuned, pool 40960), student seed 0")
    effect("s0_pool_size", "student: beam pool of 20 batches of 2048 rays", "standard head, seed 0", "test",
           s0_tuned[0], s0_head, "s0_tuned_seeds",
           "the same config file and seed; the variant is the demo run whose pool held 20 batches of 4096 rays")
    effect("s0_audio", "student: audio_lr_scale 0 (the teacher's audio encoder kept)", "standard head, seed 0",
           "test", s0_kept0, s0_tuned[0], "s0_tuned_seeds",
           "student seed 0 both, pool 40960 both")
    mean = lambda runs, what: {
        "what": what,
        "files": "; ".join(r["files"] for r in runs),
        "head_psnr": {s: sum(r["head_psnr"][s] for r in runs) / len(runs) for s in SPLITS},
    }
    effect("s0_audio_means", "student: audio_lr_scale 0 (the teacher's audio encoder kept)", "standard head, seed 0",
           "test", mean([s0_kept0, s0_kept1], "mean of student seeds 0 and 1, encoder kept"),
           mean(s0_tuned, "mean of student seeds 0, 1 and 2, encoder fine-tuned"), "s0_tuned_seeds",
           "means over the student seeds each recipe was run with (pool 40960 all)")
    effect("s1_audio", "student: audio_lr_scale 0 (the teacher's audio encoder kept)", "standard head, seed 1",
           "test", run("results/demo/xeon_s1/audio_fixed", "s1fa", "seed 1: encoder kept (pool 40960)"),
           run("results/demo/xeon_s1", "student", "seed 1: the headline student of the time (fine-tuned, pool 81920)"),
           "s1_kept_seeds", POOL_NOTE)
    effect("h2_audio", "student: audio_lr_scale 0 (the teacher's audio encoder kept)", "second head, seed 0",
           "test", run("results/demo/xeon_head2/audio_fixed", "h2fa", "second head: encoder kept (pool 40960)"),
           run("results/demo/xeon_head2", "student", "second head: the headline student of the time (fine-tuned, pool 81920)"),
           "h2_kept_seeds", POOL_NOTE)
    effect("h2_floor05", "student: opacity_floor 0", "second head, seed 0", "test",
           run("results/demo/xeon_head2", "student", "second head: the headline student of the time (fine-tuned, pool 81920)"),
           run("results/demo/xeon_head2/floor05", "floor05", "second head: opacity_floor 0.05 (fine-tuned, pool 40960)",
               pattern=EVAL_LOG),
           None, POOL_NOTE)

    abl = read_json("results/ablation/ablation.json")

    def ablation(variant):
        row = next(r for r in abl if r["variant"] == variant)
        return {"what": f"nldf ablate: {variant}", "files": "results/ablation/ablation.json",
                "psnr": {"val": row["psnr"]}, "steps": row["steps"]}

    effect("ablation_pool", "student: an active beam pool", "standard head, seed 0", "test",
           ablation("depth 28, distilled"), ablation("depth 28, distilled, no pool"), None,
           "28 x 256 students after 400 steps (early training), the val frames; whole-frame PSNR", key="psnr")

    # --- pseudo views, on the posed ablation's scenes (whole-frame PSNR) ---------------------
    P = "results/posed/epyc_realtime"
    base0 = scores_csv(f"{P}/seed0/scores.csv", "posed_pseudo_2000x1024")
    base1 = scores_csv(f"{P}/seed1/scores.csv", "posed_pseudo_2000x1024")
    mix0 = scores_csv(f"{P}/seed0/mix_range/scores.csv", "posed_pseudo_mix075")
    mix1 = scores_csv(f"{P}/seed1/mix_range/scores.csv", "posed_pseudo_mix075")
    posed_note = "15-minute real-time students after an 8-minute teacher, one run each; whole-frame PSNR"
    effect("posed_mix_s0", "student: pseudo_fraction 0.75", "standard head, seed 0", "test", mix0, base0, None,
           posed_note, key="psnr")
    effect("posed_mix_s1", "student: pseudo_fraction 0.75", "standard head, seed 1", "test", mix1, base1, None,
           posed_note, key="psnr")
    effect("posed_range15", "student: pose_range 2", "standard head, seed 0", "test", base0,
           scores_csv(f"{P}/seed0/mix_range/scores.csv", "posed_pseudo_range15"), None, posed_note, key="psnr")
    effect("posed_zoom03", "student: pseudo_zoom 0.15", "standard head, seed 0", "test", base0,
           scores_csv(f"{P}/seed0/mix_range/scores.csv", "posed_pseudo_zoom03"), None, posed_note, key="psnr")
    for eid, folder in (("posed_whole_s0", "seed0"), ("posed_whole_s1", "seed1")):
        effect(eid, "student: pseudo views of 1024 pixels", f"standard head, seed {folder[-1]}", "test",
               scores_csv(f"{P}/{folder}/scores.csv", "posed_pseudo_2000x1024"),
               scores_csv(f"{P}/{folder}/scores.csv", "posed_pseudo"), None,
               "1000 whole views against 2000 views of 1024 pixels, 15 student minutes each; whole-frame PSNR",
               key="psnr")

    # --- export ------------------------------------------------------------------------------
    kf = f"{KEPT}/xeon_s0/frontier/frontier.json"
    name = ("student 16x128 (K = 8), 600 pseudo views of 1024 px at 2x, mix 0.75, mouth 0.2, "
            "audio encoder at 0x the rate")
    fp32 = frontier(kf, name, "fp32", "ort")
    effect("export_fp16", "export: fp16 weights as shipped", "standard head, seed 0", "test", fp32,
           frontier(kf, name, "fp16", "ort"), None, "the shipped student's exports, one frontier run")
    effect("export_int8", "export: int8 offered, not shipped", "standard head, seed 0", "test", fp32,
           frontier(kf, name, "int8", "ort"), None, "the shipped student's exports, one frontier run")
    pix = "student 16x128 (K = 8), pixels only"
    effect("int8_7bit", "export: int8 weights in 7 bits", "standard head, seed 0", "test",
           frontier("results/int8/xeon_demo26/frontier_7bit.json", pix, "fp32", "ort", "psnr"),
           frontier("results/int8/xeon_demo26/frontier_7bit.json", pix, "int8", "ort", "psnr"), None,
           "int8 minus fp32 with 7-bit weights; one trained student", key="psnr")
    effect("int8_8bit", "export: int8 weights in 7 bits", "standard head, seed 0", "test",
           frontier("results/int8/xeon_demo26/frontier_8bit.json", pix, "fp32", "ort", "psnr"),
           frontier("results/int8/xeon_demo26/frontier_8bit.json", pix, "int8", "ort", "psnr"), None,
           "int8 minus fp32 with 8-bit weights; the same student", key="psnr")

    # --- upsampler (512 and 256 val, 20 and 40 frames) ---------------------------------------
    gated512 = run(up, "upsampler", "the upsampler as it is (gated, over bilinear, mouth crops)", ("val",), SHARP)
    effect("up_nearest", "upsampler: residual over bilinear, mouth crops, gate", "standard head, seed 0 at 512",
           "test", gated512,
           run("results/sharp/variants/512_nearest", "upsampler", "over nearest, crops anywhere, no gate", ("val",), SHARP),
           "u512_init", "val only; the upsampler's draw spread is its only spread")
    effect("up_ungated512", "upsampler: the colour correction gated by the opacity", "standard head, seed 0 at 512",
           "test", gated512,
           run("results/sharp/variants/512_bilinear_mouth", "upsampler", "over bilinear, mouth crops, no gate", ("val",), SHARP),
           "u512_init", "val only")
    r256 = read_json("results/sharp/xeon_256/upsampler.json")["rows"]
    g256 = next(r for r in r256 if r["way"] == "upsampler" and r["precision"] == "fp32" and r["runtime"] == "ort")
    effect("up_ungated256", "upsampler: the colour correction gated by the opacity", "standard head, seed 0 at 256",
           "test",
           {"what": "the gated upsampler (nldf bench upsampler, 40 frames)", "files": "results/sharp/xeon_256/upsampler.json",
            "head_psnr": {"val": g256["scores"][0]["head_psnr"]}},
           run("results/sharp/variants/256_ungated", "upsampler", "ungated (nldf eval)", ("val",), SHARP),
           None, "val only")

    recipe = {
        name: {"file": rel, "config": read_json(rel)}
        for name, rel in (
            ("teacher", f"{KEPT}/xeon_s0/teacher/config.json"),
            ("student", f"{KEPT}/xeon_s0/student/config.json"),
            ("upsampler", "results/sharp/xeon_512/upsampler_config.json"),
        )
    }
    # Values tried instead of the recipe's, as their runs' configs hold them.
    tried = {
        key: {"file": rel, "value": read_json(rel)["train"][key]}
        for key, rel in (
            ("ema_decay", f"{S7}/ema/config.json"),
            ("opacity_floor", f"{H2S7}/floor05/config.json"),
        )
    }
    out = {
        "note": (
            "Written by results/tuning/choices.py from the files each entry names. effect = "
            "variant minus reference, per split, at full precision (head-region PSNR in dB "
            "unless metric says psnr: the whole frame). spread = largest minus smallest of the "
            "runs listed, which differ only in the student's (or upsampler's) seed. verdict: "
            "'inside' when |effect| <= spread on that split; 'no difference' when inside on "
            "every split."
        ),
        "recipe": recipe,
        "tried": tried,
        "spreads": list(SPREADS.values()),
        "effects": EFFECTS,
    }
    with open(OUT, "w") as f:
        json.dump(out, f, indent=1)
        f.write("\n")
    for e in EFFECTS:
        eff = " / ".join(f"{v:+.2f}" for v in e["effect"].values())
        print(f"{e['id']:22} {e['scene_kind']:6} {eff:24} {e['summary']}")
    for s in SPREADS.values():
        print(f"{s['id']:22} {' / '.join(f'{v:.2f}' for v in s['spread'].values())}")


if __name__ == "__main__":
    main()
