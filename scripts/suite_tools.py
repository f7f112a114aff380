#!/usr/bin/python3
"""Small helpers the study scripts share: running odomcov, copying a suite elsewhere (its CSV
paths made absolute), reading and replacing its robot line and model block, and splitting it by
experiment name. The tool itself does the modelling (`odomcov calibrate`); these only move
files around it.
"""
import os
import re
import subprocess


def run(cmd):
    """Runs a command; its stdout, or RuntimeError with its stderr when it fails."""
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({done.returncode}): {done.stderr.strip()}")
    return done.stdout


def copy_suite(suite, to):
    """Copies a suite elsewhere, making its relative CSV paths absolute."""
    base = os.path.dirname(os.path.abspath(suite))
    with open(suite) as f:
        text = f.read()
    # plain or quoted (the suite writer quotes file names) relative paths
    text = re.sub(r"(?<=[\s\[,])([\"']?)(?!/)([^\s,\[\]{}'\"]+\.csv)\1(?=[\s,\]]|$)",
                  lambda m: m.group(1) + os.path.join(base, m.group(2)) + m.group(1), text)
    with open(to, "w") as f:
        f.write(text)


def _model_span(lines):
    """Indices of the robot line and of the model block [start, end) (None, None if absent)."""
    robot = next(i for i, line in enumerate(lines) if line.startswith("robot:"))
    start = next((i for i, line in enumerate(lines) if line.startswith("model:")), None)
    end = start
    if start is not None:
        end = start + 1
        while end < len(lines) and (lines[end].startswith(" ") or not lines[end].strip()):
            end += 1
    return robot, start, end


def model_of(suite):
    """The robot line and model block of a suite (or of calibrate's model.yaml)."""
    with open(suite) as f:
        lines = [line for line in f.read().splitlines() if not line.startswith("#")]
    robot, start, end = _model_span(lines)
    return "\n".join([lines[robot]] + (lines[start:end] if start is not None else [])) + "\n"


def set_model(suite, yaml_text):
    """Replaces the suite's robot line and model block with `yaml_text` (a robot line, then
    optionally a model block, as calibrate's model.yaml and fit's JSON `yaml` give them)."""
    with open(suite) as f:
        lines = f.read().splitlines()
    robot, start, end = _model_span(lines)
    if start is not None:
        del lines[start:end]
    new = [line for line in yaml_text.rstrip("\n").splitlines() if not line.startswith("#")]
    lines[robot] = new[0]
    at = next(i for i, line in enumerate(lines) if line.startswith("experiments:"))
    lines[at:at] = new[1:]
    with open(suite, "w") as f:
        f.write("\n".join(lines) + "\n")


def select_experiments(suite, pattern, to):
    """Copies a suite to `to` (as copy_suite) keeping only the experiments whose names match the
    regex `pattern`; returns how many runs (logged CSVs) they have."""
    copy_suite(suite, to)
    with open(to) as f:
        head, body = f.read().split("experiments:\n", 1)
    blocks = [b for b in re.split(r"(?m)^(?=  - name:)", body) if b.strip()]
    keep = [b for b in blocks if re.search(pattern, re.search(r'name: "?([^"\n]+)', b).group(1))]
    with open(to, "w") as f:
        f.write(head + "experiments:\n" + "".join(keep))
    return sum(b.count(".csv") for b in keep)
