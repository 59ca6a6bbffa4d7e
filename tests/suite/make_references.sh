#!/usr/bin/env bash
# Converged references of the scene suite (issue 21): Lantern's reference path
# tracer at a high spp on each scene of assets/scenes/suite/ (128×128), for
# `lantern equal-time` and `lantern converge --converged`.
#
# For each scene NAME it writes
#   tests/data/suite/NAME.exr      the image (linear RGB, 32-bit float), its
#                                  header holding lantern/spp, lantern/seconds,
#                                  lantern/method, lantern/seed;
#   tests/data/suite/NAME_var.exr  the variance of each pixel's mean (sample
#                                  variance / spp), from which the readers take
#                                  the reference's own noise out of the errors
#                                  they measure;
# and appends Lantern's summary line to tests/data/suite/references.log.
#
# Usage (from anywhere; builds the release binary if it is missing):
#   tests/suite/make_references.sh                 # every scene, ~1 h on one core
#   tests/suite/make_references.sh thick_cumulus   # some scenes
#   THREADS=2 SPP_DIVISOR=64 OUT=/tmp/suite tests/suite/make_references.sh  # a quick try
# Environment: LANTERN (binary, default target/release/lantern), THREADS
# (default 1), OUT (default tests/data/suite), SEED (default 1000003: other
# than the seeds equal-time renders with), SPP_DIVISOR (default 1).
set -euo pipefail
cd "$(dirname "$0")/../.."

LANTERN=${LANTERN:-target/release/lantern}
THREADS=${THREADS:-1}
OUT=${OUT:-tests/data/suite}
SEED=${SEED:-1000003}
SPP_DIVISOR=${SPP_DIVISOR:-1}

# Samples per pixel, chosen from 256-spp probes for a median per-pixel
# relative standard error of the mean of about 1.2 % on the pixels brighter
# than 5 % of the 99th percentile (reached: 1.1-1.7 %; the cumulus 1.8 %,
# the thick sphere 0.9 %, re-rendered after the Russian roulette stopped
# letting weights grow: with it the cumulus's reference had fireflies and
# 5.2 %). Seconds: wall time on one core of the 2-core development machine,
# shared with other work; the cumulus and the thick sphere on two threads.
declare -A SPP=(
    [wispy_smoke]=32768            # 146 s
    [smoke_plume]=16384            # 185 s
    [thick_cumulus]=49152          # 1773 s (2 threads)
    [thick_sphere_front_lit]=24576 # 509 s (2 threads)
    [chromatic]=49152              # 442 s
    [point_lit]=32768              # ~300 s
    [sky_lit_plume]=16384          # (issue 24: sun and clear sky)
)
ALL=(wispy_smoke smoke_plume thick_cumulus thick_sphere_front_lit chromatic point_lit sky_lit_plume)

if [[ ! -x "$LANTERN" ]]; then
    cargo build --release --locked
fi
mkdir -p "$OUT"
scenes=("$@")
if [[ ${#scenes[@]} -eq 0 ]]; then
    scenes=("${ALL[@]}")
fi
for name in "${scenes[@]}"; do
    if [[ -z "${SPP[$name]:-}" ]]; then
        echo "unknown suite scene $name (known: ${ALL[*]})" >&2
        exit 1
    fi
    spp=$(( SPP[$name] / SPP_DIVISOR ))
    (( spp >= 2 )) || spp=2
    echo "$name: $spp spp on $THREADS thread(s)…" >&2
    "$LANTERN" render "assets/scenes/suite/$name.ron" --method reference \
        --spp "$spp" --seed "$SEED" --threads "$THREADS" \
        --out "$OUT/$name.exr" --variance "$OUT/${name}_var.exr" |
        grep '^rendered' | tee -a "$OUT/references.log"
done
