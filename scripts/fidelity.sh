#!/bin/sh
# Regenerates docs/fidelity.md's "The SV-BRDF against explicit grooves" table and images:
# every scene of validation/fidelity rendered with the SV-BRDF and with explicit grooves
# (`scratches.explicit` turned on, nothing else changed), two seeds each, the explicit render
# at 4x the samples. Prints the Markdown table; the images go to docs/fidelity/.
set -e
cd "$(dirname "$0")/.."
[ $# -gt 0 ] || set -- validation/fidelity/*.toml
# (Built with the CLI, so the two share one build of the library.)
cargo build --release -p striae -p striae-cli --bins --example fidelity
target/release/examples/fidelity docs/fidelity "${FACTOR:-4}" "$@"
