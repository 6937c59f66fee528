#!/usr/bin/env python3
"""Checks the workspace's manifests (issue 18, "Manifests"):

* every member takes its dependencies' versions from the root
  `[workspace.dependencies]` (no `name = "1.2"` or `{ version = ... }` in a
  member's dependency tables);
* every member declares the workspace's `rust-version`;
* that `rust-version` is at least the one every dependency in the lock file
  declares (iceoryx2 0.10 needs 1.89): no toolchain older than ours is
  reachable here, so the minimum is checked against what the crates say;
* the Python package (`nerve-python`, built alone by maturin) resolves every
  dependency with a feature set the whole workspace also has, so that its
  build reuses the workspace's instead of compiling 70 crates again
  (python/Cargo.toml, "Feature unification").

Exit 1 with one line per problem.
"""
import json
import re
import subprocess
import sys
from pathlib import Path

root = Path(__file__).resolve().parent.parent
meta = json.loads(
    subprocess.run(
        ["cargo", "metadata", "--format-version", "1", "--locked"],
        cwd=root, check=True, capture_output=True, text=True,
    ).stdout
)
members = set(meta["workspace_members"])
problems = []


def version_tuple(v):
    return tuple(int(x) for x in re.findall(r"\d+", v)[:3]) + (0,) * (3 - len(re.findall(r"\d+", v)[:3]))


ours = None
root_toml = (root / "Cargo.toml").read_text()
m = re.search(r'^rust-version\s*=\s*"([^"]+)"', root_toml, re.M)
if not m:
    problems.append("Cargo.toml: no rust-version in [workspace.package]")
else:
    ours = m.group(1)

dep_table = re.compile(r"^\[(?:target\.[^\]]+\.)?(dev-|build-)?dependencies\]\s*$")
for pkg in meta["packages"]:
    if pkg["id"] not in members:
        continue
    manifest = Path(pkg["manifest_path"])
    rel = manifest.relative_to(root)
    if ours and pkg.get("rust_version") != ours:
        problems.append(f"{rel}: rust-version {pkg.get('rust_version')} is not the workspace's {ours} (use rust-version.workspace = true)")
    in_deps = False
    for n, line in enumerate(manifest.read_text().splitlines(), 1):
        s = line.strip()
        if s.startswith("["):
            in_deps = bool(dep_table.match(s))
            continue
        if not in_deps or not s or s.startswith("#"):
            continue
        if "workspace = true" in s or ".workspace = true" in s or "path =" in s:
            continue
        problems.append(f"{rel}:{n}: `{s}` fixes a version in a member; put it in the root [workspace.dependencies] and write `NAME.workspace = true`")

if ours:
    for pkg in meta["packages"]:
        rv = pkg.get("rust_version")
        if pkg["id"] in members or not rv:
            continue
        if version_tuple(rv) > version_tuple(ours):
            problems.append(f"{pkg['name']} {pkg['version']} needs Rust {rv}, above the workspace's rust-version {ours}: raise it in Cargo.toml")



def feature_sets(edges, *selection):
    """{"name vX": {"f1,f2", ...}} for the packages `cargo tree` resolves for the selection."""
    out = subprocess.run(
        ["cargo", "tree", "--locked", "-e", edges, "--prefix", "none", "-f", "{p} [{f}]", *selection],
        cwd=root, check=True, capture_output=True, text=True,
    ).stdout
    sets = {}
    for line in out.splitlines():
        m = re.match(r"(\S+ v\S+)(?: \(.*?\))? \[(.*)\]", line.strip())
        if m:
            sets.setdefault(m.group(1), set()).add(m.group(2))
    return sets


workspace_sets = feature_sets("normal,build,dev", "--workspace")
for name, sets in sorted(feature_sets("normal,build", "-p", "nerve-python").items()):
    extra = sets - workspace_sets.get(name, set())
    if extra:
        problems.append(
            f"python/Cargo.toml: `{name}` resolves with features {sorted(extra)} when the Python package is built alone, "
            f"which the workspace never builds (it has {sorted(workspace_sets.get(name, set()))}): "
            "name the crate in its feature unification with the workspace's features, or maturin compiles it and its dependents again"
        )

for p in problems:
    print(p)
if problems:
    sys.exit(1)
print(f"manifests: {len(members)} members take their versions from the workspace; rust-version {ours} covers every dependency")
