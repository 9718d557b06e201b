#!/usr/bin/env bash
# Records the shipped glove trajectories of the simulated operator into recordings/trajectories/
# (see recordings/README.md): for each script, a copy of launch/record-glove.toml with the script
# and the file name changed, run for DURATION seconds (default 16) on its own iceoryx2 prefix.
#
#   scripts/record-glove-trajectories.sh [NAME...]   # default: all six
#
# Run from the repository's top folder after
# `cargo build --release -p teleop -p teleop-glove -p teleop-sim-glove -p teleop-recorder`;
# TELEOP names another `teleop` binary (its folder must hold the other three).
set -euo pipefail

teleop=${TELEOP:-target/release/teleop}
duration=${DURATION:-16}
names=("$@")
if [ ${#names[@]} -eq 0 ]; then
    names=(grasp pinch-index pinch-middle pinch-ring open-close free)
fi

for name in "${names[@]}"; do
    out=recordings/trajectories/$name.mcap
    # The copy sits beside the original so that its relative paths hold; the recorder stores
    # its text as the `launch` metadata record.
    launch=launch/.record-glove-$name.toml
    trap 'rm -f "$launch"' EXIT
    sed -e "s|trajectories/grasp.mcap|trajectories/$name.mcap|" \
        -e "s|\"--script\", \"grasp\"|\"--script\", \"$name\"|" \
        launch/record-glove.toml >"$launch"
    rm -f "$out" # the recorder never overwrites
    "$teleop" --ipc-prefix trajrec_ launch "$launch" --duration "$duration"
    rm -f "$launch"
    "$teleop" recordings info "$out"
done
