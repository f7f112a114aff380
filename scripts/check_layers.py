#!/usr/bin/env python3
"""Checks the library's layering (docs/architecture.md) against the includes in the tree.

The `Layers:` line of docs/architecture.md names the folders of src/ and include/odomcov/,
bottom to top. A file in layer L may include headers of L and of the layers below it, never of
a layer above. The check also holds the tree to its shape:
  * no source or header file loose in src/ (only CMakeLists.txt);
  * every folder of src/ is a layer or `cli` (the top, above every layer), and every layer has
    its folder;
  * include/odomcov/ holds, besides the layer folders, only the forwarding headers of the old
    flat include paths, and no file of the library includes a forwarding header.

Usage: check_layers.py [ROOT]   (exit 0: clean; 1: each problem on its own line)
       check_layers.py --count ROOT   print the number of upward includes only
"""
import os
import re
import sys

INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)
SOURCE_SUFFIXES = (".cpp", ".hpp", ".h", ".cc")


def read_layers(root):
    with open(os.path.join(root, "docs", "architecture.md"), encoding="utf-8") as f:
        for line in f:
            m = re.match(r"^Layers:\s*(.+?)\s*$", line)
            if m:
                return [x.strip() for x in m.group(1).split(",") if x.strip()]
    raise SystemExit("docs/architecture.md: no 'Layers:' line")


def layer_of(root, path, ranks):
    """The layer a file belongs to, or None (a forwarding header, or outside the library)."""
    rel = os.path.relpath(path, root).split(os.sep)
    if rel[0] == "src" and len(rel) > 2 and rel[1] in ranks:
        return rel[1]
    if rel[:2] == ["include", "odomcov"] and len(rel) > 3 and rel[2] in ranks:
        return rel[2]
    return None


def resolve(root, including_file, name):
    for base in (os.path.dirname(including_file), os.path.join(root, "src"),
                 os.path.join(root, "include")):
        candidate = os.path.normpath(os.path.join(base, name))
        if os.path.isfile(candidate):
            return candidate
    return None


def library_files(root):
    for top in ("src", os.path.join("include", "odomcov")):
        for dirpath, _, files in os.walk(os.path.join(root, top)):
            for f in sorted(files):
                if f.endswith(SOURCE_SUFFIXES):
                    yield os.path.join(dirpath, f)


def check(root):
    layers = read_layers(root)
    ranks = {name: i for i, name in enumerate(layers)}
    ranks["cli"] = len(layers)  # the command-line tool sits above every layer
    problems, upward = [], 0

    src = os.path.join(root, "src")
    for entry in sorted(os.listdir(src)):
        full = os.path.join(src, entry)
        if os.path.isfile(full) and entry.endswith(SOURCE_SUFFIXES):
            problems.append(f"src/{entry}: loose in src/, belongs in a layer folder")
        elif os.path.isdir(full) and entry not in ranks:
            problems.append(f"src/{entry}/: not a layer of docs/architecture.md")
    for layer in layers:
        if not os.path.isdir(os.path.join(src, layer)):
            problems.append(f"src/{layer}/: layer of docs/architecture.md has no folder")

    forwarding = os.path.join(root, "include", "odomcov")
    for entry in sorted(os.listdir(forwarding)):
        full = os.path.join(forwarding, entry)
        if os.path.isdir(full) and entry not in ranks:
            problems.append(f"include/odomcov/{entry}/: not a layer of docs/architecture.md")
        if os.path.isfile(full):
            with open(full, encoding="utf-8") as f:
                targets = INCLUDE.findall(f.read())
            if not targets or any(layer_of(root, resolve(root, full, t) or "", ranks) is None
                                  for t in targets):
                problems.append(f"include/odomcov/{entry}: a loose header must only forward "
                                "to layered headers")

    for path in library_files(root):
        layer = layer_of(root, path, ranks)
        if layer is None:
            continue  # forwarding headers, checked above
        with open(path, encoding="utf-8") as f:
            text = f.read()
        for m in INCLUDE.finditer(text):
            name = m.group(1)
            line = text.count("\n", 0, m.start()) + 1
            where = f"{os.path.relpath(path, root)}:{line}"
            target = resolve(root, path, name)
            if target is None:
                problems.append(f"{where}: #include \"{name}\" not found in the tree")
                continue
            target_layer = layer_of(root, target, ranks)
            if target_layer is None:
                problems.append(f"{where}: #include \"{name}\" is a forwarding header; "
                                "include the layered path")
            elif ranks[target_layer] > ranks[layer]:
                upward += 1
                problems.append(f"{where}: {layer} includes \"{name}\" of the higher layer "
                                f"{target_layer}")
    return problems, upward


def main(argv):
    count_only = "--count" in argv
    args = [a for a in argv[1:] if a != "--count"]
    root = os.path.abspath(args[0] if args else os.path.join(os.path.dirname(__file__), ".."))
    problems, upward = check(root)
    if count_only:
        print(upward)
        return 0
    for p in problems:
        print(p)
    if problems:
        print(f"check_layers: {len(problems)} problem(s), {upward} upward include(s)")
        return 1
    print("check_layers: clean")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
