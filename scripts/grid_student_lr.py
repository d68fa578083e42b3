#!/usr/bin/env python3
"""The grid teacher's student at twice the learning rate, against the recipe's students.

Reads results/grid/student_lr/test_<scene>/metrics_{val,novel,voice}.json (`nldf eval` of
a test scene's grid teacher and its student trained at 1e-3, label `student_lr1e3`) and
the students it is compared with: the MLP teacher's student and the grid teacher's student
at the old 5e-4, from the scene's runs in results/grid/summary.json when the grid teacher
trained again scores exactly as that one did, else from the same folder (`student_base`
beside the new student, the MLP demo's in `mlp/`). Writes results/grid/student_lr/summary.json:
per scene and split, each model's head and mouth PSNR and the differences the issue
bounds (the new student minus the MLP teacher's student: +1.5; minus its own teacher:
-0.5 on val, -1.0 on novel and voice). Where results/grid/student_lr/steps9k/test_<scene>/
(or steps18k/, steps36k/) holds `nldf eval`'s files of the same teacher and its student
trained at 1e-3 for 9000 steps, label `lr1e3_9k` (or 18000, `lr1e3_18k`; 36000,
`lr1e3_36k`), that student is added with the
same differences and its gain over the 4500-step one. Under `demos`, each whole `nldf demo`
of the grid recipe in results/demo/grid_epyc_<scene>/ (teacher and 36000-step student in one
run): the same differences, its teacher's steps and its teacher against the committed grid
run of results/grid/summary.json (0: the same teacher). Prints a table.
"""

import json
import os

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "results", "grid")
SPLITS = ("val", "novel", "voice")
METRICS = ("head_psnr", "mouth_psnr")
LABEL = "student_lr1e3"
# The longer students: their label and folder.
LONGER = (("lr1e3_9k", "steps9k"), ("lr1e3_18k", "steps18k"), ("lr1e3_36k", "steps36k"))


def load(path):
    with open(path) as f:
        return json.load(f)


def split_metrics(d, label):
    """`label`'s head and mouth PSNR per split, from `nldf eval`'s files in folder `d`."""
    out = {}
    for split in SPLITS:
        m = {x["label"]: x for x in load(os.path.join(d, f"metrics_{split}.json"))["models"]}
        out[split] = {k: m[label][k] for k in METRICS}
    return out


def minus(models, a, b):
    """`models[a]` minus `models[b]`, per split and metric."""
    return {s: {k: models[a][s][k] - models[b][s][k] for k in METRICS} for s in SPLITS}


def committed_student(run):
    """The student's head and mouth PSNR per split in one of summary.json's runs."""
    return {s: {k: run["models"]["student"][s][k] for k in METRICS} for s in SPLITS}


def main():
    old = {s["scene"]: s for s in load(os.path.join(ROOT, "summary.json"))["scenes"]}
    scenes = []
    for scene in ("s0", "s1", "h2"):
        d = os.path.join(ROOT, "student_lr", f"test_{scene}")
        if not os.path.isdir(d):
            continue
        models = {"teacher": split_metrics(d, "teacher"), "lr1e3": split_metrics(d, LABEL)}
        runs = old[scene]["runs"]
        then = {s: runs["grid"]["models"]["teacher"][s]["head_psnr"] for s in SPLITS}
        again = {s: models["teacher"][s]["head_psnr"] - then[s] for s in SPLITS}
        if os.path.isdir(os.path.join(d, "mlp")):
            # The scene's committed runs are older than its scene (their teacher scores
            # otherwise): both students are trained again beside the new one.
            models["grid_student"] = split_metrics(d, "student_base")
            models["mlp_student"] = split_metrics(os.path.join(d, "mlp"), "student")
            source = "this folder"
        else:
            if any(abs(v) > 1e-9 for v in again.values()):
                raise SystemExit(f"{scene}: the teacher differs from summary.json's")
            models["grid_student"] = committed_student(runs["grid"])
            models["mlp_student"] = committed_student(runs["mlp"])
            source = "results/grid/summary.json"

        longer = []
        for label, folder in LONGER:
            dl = os.path.join(ROOT, "student_lr", folder, f"test_{scene}")
            if os.path.isdir(dl):
                if split_metrics(dl, "teacher") != models["teacher"]:
                    raise SystemExit(f"{scene}: {label}'s teacher is another one")
                models[label] = split_metrics(dl, label)
                longer.append(label)

        entry = {
            "scene": scene,
            "baselines_from": source,
            "models": models,
            "lr1e3_minus_mlp_student": minus(models, "lr1e3", "mlp_student"),
            "lr1e3_minus_grid_student": minus(models, "lr1e3", "grid_student"),
            "lr1e3_minus_teacher": minus(models, "lr1e3", "teacher"),
            # The grid teacher trained again here against the one of summary.json (head
            # PSNR): the recipe is pinned in steps, so 0 says the scene and teacher are
            # the same.
            "teacher_again_minus_then": again,
        }
        for label in longer:
            entry[f"{label}_minus_mlp_student"] = minus(models, label, "mlp_student")
            entry[f"{label}_minus_lr1e3"] = minus(models, label, "lr1e3")
            entry[f"{label}_minus_teacher"] = minus(models, label, "teacher")
        scenes.append(entry)
    demos = []
    for scene, mlp_dir in (("s0", None), ("h2", os.path.join(ROOT, "student_lr", "test_h2", "mlp"))):
        d = os.path.join(ROOT, "..", "demo", f"grid_epyc_{scene}")
        if not os.path.isdir(d):
            continue
        models = {"teacher": split_metrics(d, "teacher"), "student": split_metrics(d, "student")}
        runs = old[scene]["runs"]
        if mlp_dir is None:
            models["mlp_student"] = committed_student(runs["mlp"])
        else:
            models["mlp_student"] = split_metrics(mlp_dir, "student")
        steps = load(os.path.join(d, "metrics_val.json"))["models"][0]["step"]
        demos.append({
            "scene": scene,
            "teacher_steps": steps,
            "models": models,
            "student_minus_teacher": minus(models, "student", "teacher"),
            "student_minus_mlp_student": minus(models, "student", "mlp_student"),
            "teacher_minus_committed": {
                s: models["teacher"][s]["head_psnr"]
                - runs["grid"]["models"]["teacher"][s]["head_psnr"] for s in SPLITS},
        })
    with open(os.path.join(ROOT, "student_lr", "summary.json"), "w") as f:
        json.dump({"scenes": scenes, "demos": demos}, f, indent=1)
    for e in demos:
        for s in SPLITS:
            print(f"demo {e['scene']} {s:5} teacher step {e['teacher_steps']} "
                  f"vs teacher {e['student_minus_teacher'][s]['head_psnr']:+.2f} "
                  f"vs mlp {e['student_minus_mlp_student'][s]['head_psnr']:+.2f} "
                  f"teacher vs committed {e['teacher_minus_committed'][s]:+.3f}")
    for e in scenes:
        for s in SPLITS:
            m = e["models"]
            print(f"{e['scene']} {s:5} teacher {m['teacher'][s]['head_psnr']:.2f} "
                  f"lr1e3 {m['lr1e3'][s]['head_psnr']:.2f} "
                  f"grid student {m['grid_student'][s]['head_psnr']:.2f} "
                  f"mlp student {m['mlp_student'][s]['head_psnr']:.2f}  "
                  f"vs mlp {e['lr1e3_minus_mlp_student'][s]['head_psnr']:+.2f} "
                  f"vs 5e-4 {e['lr1e3_minus_grid_student'][s]['head_psnr']:+.2f} "
                  f"vs teacher {e['lr1e3_minus_teacher'][s]['head_psnr']:+.2f} "
                  f"teacher again {e['teacher_again_minus_then'][s]:+.3f}")
            for label, _ in LONGER:
                if label in m:
                    print(f"   {label} {m[label][s]['head_psnr']:.2f} "
                          f"vs mlp {e[label + '_minus_mlp_student'][s]['head_psnr']:+.2f} "
                          f"vs 4500 {e[label + '_minus_lr1e3'][s]['head_psnr']:+.2f} "
                          f"vs teacher {e[label + '_minus_teacher'][s]['head_psnr']:+.2f}")


if __name__ == "__main__":
    main()
