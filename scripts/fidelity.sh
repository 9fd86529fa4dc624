#!/bin/sh
# Regenerates docs/fidelity.md's "The SV-BRDF against explicit grooves" table and images:
# every scene of validation/fidelity rendered with the SV-BRDF and with explicit grooves
# (`scratches.explicit` turned on, nothing else changed), two seeds each, the explicit render
# at 4x the samples. Prints the Markdown table; the images go to docs/fidelity/.
set -e
cd "$(dirname "$0")/.."
[ $# -gt 0 ] || set -- validation/fidelity/*.toml
cargo run --release -p striae --example fidelity -- docs/fidelity "${FACTOR:-4}" "$@"
