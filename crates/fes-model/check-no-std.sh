#!/usr/bin/env bash
# fes-model with default features off is `no_std` + `alloc`: it must compile, and no crate in
# its dependency tree may have its `std` feature on (a dependency's `std` would bring the
# standard library back in). serde is always on (the file formats' text needs it), so there
# is no separate serde feature to check. RUSTFLAGS is left as the caller has it.
set -euo pipefail
cd "$(dirname "$0")"

cargo check -p fes-model --no-default-features

tree=$(cargo tree -p fes-model --no-default-features -e normal,features -f '{p} {f}')
# Lines are `name vX.Y.Z feat1,feat2` (a package with its enabled features) or
# `name feature "feat"` (a feature edge); either form naming `std` is an offence.
offending=$(grep -E '(feature "std"|[ ,]std(,|[[:space:]]*$))' <<<"$tree" || true)
if [[ -n "$offending" ]]; then
    echo "check-no-std: dependencies of fes-model (default features off) with std enabled:" >&2
    echo "$offending" >&2
    exit 1
fi
echo "check-no-std: fes-model builds without std and no dependency enables std"
