#!/usr/bin/env bash
# Checks the MSRV that Cargo.toml declares (`rust-version` of the workspace, which every member
# inherits) against what the build needs: no dependency resolved for this platform may declare a
# newer `rust-version`, and clippy's `incompatible_msrv` lint (run with -D warnings by
# scripts/test.sh) refuses standard-library items newer than it. Only the one toolchain of
# rustup is on the machine, so the MSRV is not compiled with; this is what can be checked without.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
triple="$(rustc -vV | sed -n 's/^host: //p')"
cargo metadata --format-version 1 --locked --filter-platform "$triple" --manifest-path "$root/Cargo.toml" |
    python3 -c '
import json, sys

def version(text):
    return tuple(int(part) for part in text.split(".")[:2])

meta = json.load(sys.stdin)
members = set(meta["workspace_members"])
packages = {p["id"]: p for p in meta["packages"]}
declared = {packages[m]["rust_version"] for m in members}
if len(declared) != 1 or None in declared:
    sys.exit(f"check-msrv: workspace members declare rust-version {sorted(map(str, declared))}; one, inherited from the workspace, is expected")
msrv = declared.pop()
resolved = [packages[node["id"]] for node in meta["resolve"]["nodes"]]
newer = sorted(
    (version(p["rust_version"]), p["name"], p["version"], p["rust_version"])
    for p in resolved
    if p["rust_version"] and version(p["rust_version"]) > version(msrv)
)
for _, name, ver, needs in newer:
    print(f"check-msrv: {name} {ver} needs Rust {needs}, above the declared rust-version {msrv}")
if newer:
    sys.exit("check-msrv: raise rust-version in Cargo.toml (or pin older dependencies)")
highest = max((version(p["rust_version"]), p["name"]) for p in resolved if p["rust_version"] and p["id"] not in members)
print(f"check-msrv: rust-version {msrv}; the most demanding dependency is {highest[1]} ({highest[0][0]}.{highest[0][1]})")
'
