#!/usr/bin/env python3
"""Bad input, damaged files and closed pipes against every binary, as a new user would try them.

Each case runs one command in a scratch directory and is judged on:
  - no panic and no abort (no "panicked" on stderr, no death by signal);
  - the exit code the contract asks for (2 for bad input, corrupt or missing files; 0 where a
    newer damaged checkpoint is skipped for an older one or a closed stdout ends quietly);
  - an `error: ...` message naming the file (or key) at fault;
  - nothing left behind (no temporary files in the directories the command wrote to);
  - no silent accept of a corrupt checkpoint or dataset (covered by the exit code: 0 is wrong there).

Usage: python3 scripts/bad_input.py [--bin target/debug] [--markdown OUT.md]
Builds nothing: run `cargo build -p sim -p data -p train -p eval` first (scripts/test.sh does).
Prints one table row per case and a summary; exits 1 when any case fails.
"""

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default=os.path.join(ROOT, "target", "debug"))
    ap.add_argument("--markdown")
    args = ap.parse_args()
    bins = {b: os.path.join(args.bin, b) for b in ("sim", "data", "train", "eval")}
    for b in bins.values():
        if not os.access(b, os.X_OK):
            sys.exit(f"error: {b}: not built (cargo build -p sim -p data -p train -p eval)")
    work = tempfile.mkdtemp(prefix="bad-input-")
    try:
        rows = Cases(bins, work).run_all()
    finally:
        shutil.rmtree(work, ignore_errors=True)
    failed = [r for r in rows if r["verdict"] != "ok"]
    lines = ["| # | case | command | exit | want | message | verdict |", "|---:|---|---|---:|---:|---|---|"]
    for i, r in enumerate(rows, 1):
        msg = r["message"].replace("|", "\\|")[:110]
        lines.append(f"| {i} | {r['case']} | `{r['cmd']}` | {r['code']} | {r['want']} | {msg} | {r['verdict']} |")
    panics = sum(r["panic"] for r in rows)
    leftovers = sum(bool(r["leftovers"]) for r in rows)
    summary = (
        f"{len(rows)} cases: {len(rows) - len(failed)} ok, {len(failed)} failed "
        f"({panics} panics/aborts, {leftovers} with leftovers)"
    )
    text = "\n".join(lines) + "\n\n" + summary + "\n"
    print(text)
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write(text)
    sys.exit(1 if failed else 0)


class Cases:
    def __init__(self, bins, work):
        self.b = bins
        self.work = work
        self.rows = []
        self.n = 0

    # --- running and judging -------------------------------------------------------------------

    def scratch(self):
        self.n += 1
        d = os.path.join(self.work, f"case{self.n:03d}")
        os.makedirs(d)
        return d

    def run(self, case, argv, want, names=(), cwd=None, watch=(), stdout_closed=False, check=None):
        """Runs argv; `names`: substrings the message must hold (the file or key at fault);
        `watch`: directories that must hold no temporary file afterwards."""
        cwd = cwd or self.scratch()
        if stdout_closed:
            r_fd, w_fd = os.pipe()
            os.close(r_fd)
            p = subprocess.run(argv, cwd=cwd, stdout=w_fd, stderr=subprocess.PIPE, timeout=600)
            os.close(w_fd)
        else:
            p = subprocess.run(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=600)
        err = p.stderr.decode(errors="replace")
        code = p.returncode
        panic = code < 0 or "panicked" in err or code == 101 or code == 134
        lines = [l for l in err.splitlines() if l.startswith("error")]
        message = lines[-1] if lines else err.strip().splitlines()[-1] if err.strip() else ""
        left = []
        for d in watch:
            for dirpath, dirnames, filenames in os.walk(d):
                for n in filenames + dirnames:
                    if n.endswith(".tmp") or n.startswith(".tmp") or n.endswith(".partial"):
                        left.append(os.path.join(dirpath, n))
        problems = []
        if panic:
            problems.append("panic/abort")
        if code != want:
            problems.append(f"exit {code}")
        if want == 2 and not message.startswith("error: "):
            problems.append("no error line")
        missing = [n for n in names if n not in err]
        if missing:
            problems.append("does not name " + ", ".join(missing))
        if want == 2 and len(lines) > 1:
            problems.append(f"{len(lines)} error lines")
        if left:
            problems.append("leftovers: " + ", ".join(os.path.basename(x) for x in left))
        if check:
            extra = check(p, err)
            if extra:
                problems.append(extra)
        shown = [os.path.basename(a) if os.path.isabs(a) else a for a in argv]
        self.rows.append(
            dict(
                case=case,
                cmd=" ".join(shown)[:90],
                code=code,
                want=want,
                message=message.replace(self.work + "/", ""),
                panic=panic,
                leftovers=left,
                verdict="ok" if not problems else "FAIL: " + "; ".join(problems),
            )
        )
        return p

    # --- fixtures ------------------------------------------------------------------------------

    def dataset(self):
        """A small pixel dataset (synthetic episodes) and a config that trains on it."""
        d = os.path.join(self.work, "data")
        subprocess.run([self.b["data"], "synth", "--out", d, "--episodes", "3", "--steps", "40", "--size", "32"],
                       check=True, capture_output=True)
        subprocess.run([self.b["data"], "stats", d, "--val-fraction", "0.34"], check=True, capture_output=True)
        return d

    def config(self, data_dir, extra="", steps=4):
        text = open(os.path.join(ROOT, "configs", "tiny.toml")).read()
        text = text.replace('dir = "datasets/tiny"', f'dir = "{data_dir}"')
        text = re.sub(r"^generate = .*\n", "", text, flags=re.M)
        text = text.replace("steps = 400", f"steps = {steps}").replace("checkpoint_every = 100", "checkpoint_every = 2")
        text = text.replace("val_every = 100", "val_every = 2").replace("warmup_steps = 20", "warmup_steps = 1")
        return text + extra

    def write(self, path, text):
        with open(path, "w" if isinstance(text, str) else "wb") as f:
            f.write(text)
        return path

    def trained_run(self, data_dir, name):
        cfg = self.write(os.path.join(self.work, f"{name}.toml"), self.config(data_dir))
        run = os.path.join(self.work, name)
        subprocess.run([self.b["train"], cfg, "--run-dir", run, "--quiet"], check=True, capture_output=True)
        return cfg, run

    # --- the cases -------------------------------------------------------------------------------

    def run_all(self):
        data = self.dataset()
        self.config_cases(data)
        self.bddl_cases()
        self.dataset_cases(data)
        self.checkpoint_cases(data)
        self.generate_cases()
        self.pipe_cases(data)
        self.argument_cases()
        return self.rows

    def config_cases(self, data):
        base = self.config(data)
        edits = [
            ("unknown key", base.replace("warmup_steps", "warmup_stpes"), "warmup_stpes"),
            ("wrong type", base.replace("batch_size = 8", 'batch_size = "eight"'), "expected usize"),
            ("TOML syntax", base.replace("[train]", "[train"), "line"),
            ("image_size [0, 0]", base.replace("image_size = [32, 32]", "image_size = [0, 0]"), "image_size"),
            ("image_size 100000²", base.replace("image_size = [32, 32]", "image_size = [100000, 100000]"), "image_size"),
            ("window.past 100000", base.replace("window = { past = 2, future = 1 }", "window = { past = 100000, future = 1 }"), "window.past"),
            ("slots.dim 2^20", base.replace("slots = { num_slots = 4, dim = 32 }", "slots = { num_slots = 4, dim = 1048576 }"), "slots.dim"),
            ("grad_clip nan", base.replace("grad_clip = 1.0", "grad_clip = nan"), "grad_clip"),
            ("weight_decay nan", base.replace("weight_decay = 1e-2", "weight_decay = nan"), "weight_decay"),
            ("lr 0", base.replace("lr = 1e-3", "lr = 0.0"), "train.lr"),
            ("lr inf", base.replace("lr = 1e-3", "lr = inf"), "train.lr"),
            ("steps 0", base.replace("steps = 4", "steps = 0", 1), "train.steps"),
            ("batch_size 0", base.replace("batch_size = 8", "batch_size = 0"), "batch_size"),
            ("beta2 1", base.replace("[train]", "[train]\nbeta2 = 1.0"), "beta"),
            ("loss weight nan", base + "\n[train.loss_weights]\nwindow = nan\n", "loss_weights.window"),
            ("final_lr_fraction 2", base.replace("[train]", "[train]\nfinal_lr_fraction = 2.0"), "final_lr_fraction"),
            ("unknown variant", base.replace('variant = "e_slotssm"', 'variant = "slotssm"'), "model.variant"),
            ("unknown backend", base.replace('kind = "flex"', 'kind = "cuda"'), "cuda"),
            ("decoder.heads 0", base.replace("decoder = { width = 64, layers = 1, horizon = 2 }", "decoder = { width = 64, layers = 1, horizon = 2, heads = 0 }"), "heads"),
            ("data.window 0", base.replace("window = 4", "window = 0"), "data.window"),
            ("missing data.dir", base.replace(f'dir = "{data}"', 'dir = "/nonexistent/data"'), "/nonexistent/data"),  # names the directory
            ("empty file", "", "missing field"),
            ("binary garbage", "\x00\x01\x02\xff" * 10, "cfg.toml"),
        ]
        for case, text, key in edits:
            d = self.scratch()
            p = self.write(os.path.join(d, "cfg.toml"), text)
            names = (key,) if case == "missing data.dir" else ("cfg.toml", key)
            self.run(f"config: {case}", [self.b["train"], p, "--run-dir", os.path.join(d, "run"), "--quiet"],
                     2, names=names, cwd=d, watch=(d,))
        d = self.scratch()
        p = self.write(os.path.join(d, "cfg.toml"), base)
        self.run("config: --steps 0", [self.b["train"], p, "--steps", "0"], 2, names=("--steps",), cwd=d)
        self.run("config: --set unknown key", [self.b["train"], p, "--set", "train.stepz=3"], 2, names=("stepz",), cwd=d)
        self.run("config: missing file", [self.b["train"], os.path.join(d, "nope.toml")], 2, names=("nope.toml",), cwd=d)

    def bddl_cases(self):
        t1 = open(os.path.join(ROOT, "sim", "tasks", "libero_mem", "t1.bddl")).read()
        g = t1.index("(:goal")
        deep = t1[:g] + "(:goal " + "(And " * 10000 + "(On akita_black_bowl_1 plate_1)" + ")" * 10000 + "))\n"
        files = [
            ("goal nested 10 000 deep", deep, "nested deeper"),
            ("200 000 balanced parens", "(" * 100000 + ")" * 100000, "nested deeper"),
            ("unbalanced", t1 + ")", "no matching"),
            ("never closed", t1[:-10], "never closed"),
            ("unknown predicate", t1.replace("(And (On akita_black_bowl_1 plate_1))", "(And (Levitates akita_black_bowl_1 plate_1))"), "levitates"),
            ("unknown category", t1.replace("akita_black_bowl_1 - akita_black_bowl", "akita_black_bowl_1 - flying_saucer"), "flying_saucer"),
            ("inverted range", t1.replace("(-0.25 -0.15 0.12 -0.01)", "(0.12 -0.15 -0.25 -0.01)"), "inverted rectangle"),
            ("no fixtures", t1.replace("(:fixtures\n    kitchen_table - kitchen_table\n    wooden_cabinet_1 - wooden_cabinet\n  )\n\n  (:objects\n", "(:objects\n    kitchen_table - kitchen_table\n    wooden_cabinet_1 - wooden_cabinet\n"), "fixtures"),
            ("unknown problem class", t1.replace("(problem LIBERO_Kitchen_Tabletop_Manipulation)", "(problem Moon_Base)"), "problem class"),
            ("unknown name in goal", t1.replace("(And (On akita_black_bowl_1 plate_1))", "(And (On akita_black_bowl_9 plate_1))"), "akita_black_bowl_9"),
            ("10 000 signs in a yaw", t1.replace("(0.0 0.0)", "(" + "-" * 10000 + "1 0)", 1), "x.bddl"),
            ("empty file", "", "x.bddl"),
            ("binary garbage", "\x00\x01(\x02\xff)" * 20, "x.bddl"),
        ]
        for case, text, key in files:
            d = self.scratch()
            p = self.write(os.path.join(d, "x.bddl"), text)
            want = 0 if case == "10 000 signs in a yaw" else 2
            names = () if want == 0 else ("x.bddl", key)
            self.run(f"bddl: {case} (render)", [self.b["sim"], "render", "--task", p, "--out", os.path.join(d, "o.png")],
                     want, names=names, cwd=d, watch=(d,))
            if want == 2:
                self.run(f"bddl: {case} (generate)", [self.b["sim"], "generate", "--task", p, "--out", os.path.join(d, "g"),
                                                       "--episodes", "2", "--val", "1", "--size", "16"], 2, names=names, cwd=d, watch=(d,))
                self.run(f"bddl: {case} (eval)", [self.b["eval"], "--policy", "zero", "--tasks", p, "--episodes", "1",
                                                   "--out", os.path.join(d, "e")], 2, names=names, cwd=d, watch=(d,))
        d = self.scratch()
        self.run("bddl: missing file", [self.b["sim"], "render", "--task", os.path.join(d, "nope.bddl"), "--out", os.path.join(d, "o.png")],
                 2, names=("nope.bddl",), cwd=d)

    def dataset_cases(self, data):
        idx = json.load(open(os.path.join(data, "index.json")))
        ep = idx["episodes"][0]["file"]
        good = open(os.path.join(data, ep), "rb").read()

        def damaged(case, mutate, key=None, want=2):
            d = self.scratch()
            dd = os.path.join(d, "data")
            shutil.copytree(data, dd)
            mutate(dd)
            cfg = self.write(os.path.join(d, "cfg.toml"), self.config(dd))
            self.run(f"dataset: {case}", [self.b["train"], cfg, "--run-dir", os.path.join(d, "run"), "--quiet"], want,
                     names=(key or ep,), cwd=d, watch=(d,),
                     check=lambda p, err: None if not os.path.exists(os.path.join(d, "run", "metrics.jsonl"))
                     or open(os.path.join(d, "run", "metrics.jsonl")).read().strip() == "" else "trained before noticing")

        def flip(at):
            def f(dd):
                b = bytearray(good)
                b[at % len(b)] ^= 0x04
                self.write(os.path.join(dd, ep), bytes(b))
            return f

        damaged("truncated episode", lambda dd: self.write(os.path.join(dd, ep), good[: len(good) // 2]))
        damaged("one bit flipped mid-file", flip(len(good) // 2))
        damaged("one bit flipped in the header record", flip(20))
        damaged("one bit flipped near the end", flip(len(good) - 40))
        damaged("empty episode file", lambda dd: self.write(os.path.join(dd, ep), b""))
        damaged("episode renamed away", lambda dd: os.rename(os.path.join(dd, ep), os.path.join(dd, ep + ".bak")))
        damaged("index.json broken JSON", lambda dd: self.write(os.path.join(dd, "index.json"), "{\"format\": "), "index.json")
        damaged("index.json empty", lambda dd: self.write(os.path.join(dd, "index.json"), ""), "index.json")

        def wrong_len(dd):
            j = json.load(open(os.path.join(dd, "index.json")))
            j["episodes"][0]["length"] += 1
            self.write(os.path.join(dd, "index.json"), json.dumps(j))
        damaged("index.json wrong length", wrong_len)
        damaged("index.json missing", lambda dd: os.remove(os.path.join(dd, "index.json")), "index.json")
        d = self.scratch()
        self.write(os.path.join(d, "cut.mcap"), good[:1000])
        self.run("data inspect: truncated", [self.b["data"], "inspect", os.path.join(d, "cut.mcap")], 2, names=("cut.mcap",), cwd=d)
        self.write(os.path.join(d, "text.mcap"), "hello")
        self.run("data inspect: not mcap", [self.b["data"], "inspect", os.path.join(d, "text.mcap")], 2, names=("text.mcap",), cwd=d)
        self.run("data stats: empty dir", [self.b["data"], "stats", d + "/empty_sub"], 2, names=("empty_sub",), cwd=d)

    def checkpoint_cases(self, data):
        def damaged(case, mutate, want, names, both=False):
            cfg, run = self.trained_run(data, f"ck{self.n}")
            cks = sorted(x for x in os.listdir(os.path.join(run, "checkpoints")) if x.startswith("step_"))
            if not both:
                # Only the newest is damaged: readers fall back to the older one.
                mutate(os.path.join(run, "checkpoints", cks[-1]))
            else:
                for c in cks:
                    mutate(os.path.join(run, "checkpoints", c))
            d = self.scratch()
            self.run(f"checkpoint: {case} (eval)", [self.b["eval"], "--run", run, "--tasks", "t1", "--episodes", "1",
                                                     "--out", os.path.join(d, "e"), "--image-size", "32"],
                     want, names=names, cwd=d, watch=(d, run),
                     check=lambda p, err: None if want != 0 or "step_000000002" in err else "does not say it used step 2")
            self.run(f"checkpoint: {case} (resume)", [self.b["train"], cfg, "--run-dir", run, "--quiet", "--steps", "6"],
                     want, names=names, cwd=d, watch=(run,))

        def flip_bits(ck):
            p = os.path.join(ck, "model.bpk")
            b = bytearray(open(p, "rb").read())
            for k in range(50):
                b[(k * 7919) % len(b)] ^= 1 << (k % 8)
            self.write(p, bytes(b))

        def truncate(ck):
            p = os.path.join(ck, "model.bpk")
            self.write(p, open(p, "rb").read()[:100])

        def state_step(ck):
            p = os.path.join(ck, "state.json")
            self.write(p, re.sub(r'"step": \d+', '"step": 999999', open(p).read(), count=1))

        def state_garbage(ck):
            self.write(os.path.join(ck, "state.json"), "{ not json")

        for case, mutate in [("50 flipped bits in model.bpk", flip_bits), ("truncated model.bpk", truncate),
                             ("state.json says step 999999", state_step), ("state.json garbage", state_garbage)]:
            damaged(case + ", newest only", mutate, 0, ())
            damaged(case + ", every one", mutate, 2, ("checkpoints/step_",), both=True)
        d = self.scratch()
        self.run("checkpoint: no run dir", [self.b["eval"], "--run", os.path.join(d, "nope")], 2, names=("nope",), cwd=d)

    def generate_cases(self):
        d = self.scratch()
        out = os.path.join(d, "g")
        subprocess.run([self.b["sim"], "generate", "--task", "t1", "--out", out, "--episodes", "2", "--val", "1",
                        "--size", "16", "--seed", "0"], check=True, capture_output=True)
        self.run("generate: another seed into the directory", [self.b["sim"], "generate", "--task", "t1", "--out", out,
                                                               "--episodes", "2", "--val", "1", "--size", "16", "--seed", "5"],
                 2, names=("seed 0 → 5", "--force"), cwd=d, watch=(out,))
        self.run("generate: another image size", [self.b["sim"], "generate", "--task", "t1", "--out", out,
                                                  "--episodes", "2", "--val", "1", "--size", "32"],
                 2, names=("image_size 16 → 32",), cwd=d, watch=(out,))
        self.write(os.path.join(out, ".episode-killed.mcap.tmp"), b"partial")
        self.run("generate: rerun after a kill", [self.b["sim"], "generate", "--task", "t1", "--out", out,
                                                  "--episodes", "2", "--val", "1", "--size", "16"], 0, cwd=d, watch=(out,))
        for case, extra, key in [("episodes 0", ["--episodes", "0"], "episodes"), ("val = episodes", ["--episodes", "2", "--val", "2"], "val"),
                                 ("size 0", ["--size", "0"], "size"), ("workers 0", ["--workers", "0"], "workers"),
                                 ("unknown task", ["--task", "t99"], "t99")]:
            task = [] if "--task" in extra else ["--task", "t1"]
            argv = [self.b["sim"], "generate", "--out", os.path.join(d, "x")] + task + extra
            self.run(f"generate: {case}", argv, 2, names=(key,), cwd=d, watch=(d,))

    def pipe_cases(self, data):
        d = self.scratch()
        ep = os.path.join(data, json.load(open(os.path.join(data, "index.json")))["episodes"][0]["file"])
        cfg = self.write(os.path.join(d, "cfg.toml"), self.config(data, steps=2))
        for case, argv in [
            ("sim tasks", [self.b["sim"], "tasks"]),
            ("sim info", [self.b["sim"], "info"]),
            ("data inspect", [self.b["data"], "inspect", ep]),
            ("data stats", [self.b["data"], "stats", data, "--val-fraction", "0.34"]),
            ("train", [self.b["train"], cfg, "--run-dir", os.path.join(d, "run"), "--quiet"]),
            ("eval", [self.b["eval"], "--policy", "zero", "--tasks", "t1", "--episodes", "1", "--out", os.path.join(d, "e")]),
        ]:
            def results_written(p, err, case=case):
                if case == "eval" and not os.path.exists(os.path.join(d, "e", "results.json")):
                    return "results.json not written"
                return None
            self.run(f"closed stdout: {case} | true", argv, 0, cwd=d, stdout_closed=True, check=results_written)

    def argument_cases(self):
        d = self.scratch()
        self.run("eval: unknown task", [self.b["eval"], "--policy", "zero", "--tasks", "t99"], 2, names=("t99",), cwd=d)
        self.run("eval: --run without checkpoint", [self.b["eval"], "--run", d], 2, names=(os.path.basename(d),), cwd=d)
        self.run("sim render: size 0", [self.b["sim"], "render", "--task", "t1", "--size", "0", "--out", os.path.join(d, "o.png")],
                 2, names=("size",), cwd=d)
        self.run("sim render: missing out dir", [self.b["sim"], "render", "--task", "t1", "--out", os.path.join(d, "no", "o.png")],
                 2, names=("does not exist",), cwd=d)


if __name__ == "__main__":
    main()
