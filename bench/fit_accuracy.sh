#!/usr/bin/env bash
# The fit's acceptance figures (issue 8, docs/fitting.md) on the simulated 640×427 captures, and
# their spread.
#
# For each lens (tests/data/fit/sim-<lens>-640.toml, 0–30° at 0.2°, simulated on first use), each
# noise seed (the rig's [sensor] seed) and each edge weight λ, fits the capture with a report,
# then rates the model and the report's per-frame fits against the ground truth with fit-eval.
# Prints one line per fit and, per lens, the mean and the range over λ × seeds of recall /
# precision / median PSNR / median centroid error (px, and % of the ghost's radius) / median flux
# error / continuity / the median gap to a ceiling (with --ceiling), and the fit's seconds.
#
# Why several λ and seeds: a fit's figures move with small changes of its input; one fit cannot
# tell a change from that spread, the mean set against its range can tell changes larger than it.
#
#   bench/fit_accuracy.sh [--lenses "heliar tessar tessar-rggb nikon"] [--seeds "1 2 3"]
#                         [--lambdas "0.98 0.99 1 1.01 1.02"] [--holdout] [--out DIR]
#                         [--ceiling SIGMA] [--flarekit BIN] [--eval-only] [-- more flarekit fit options]
#
# --eval-only rates the fits already in DIR again (after a change to fit-eval) without fitting.
# --holdout fits every other frame (fit --holdout odd) and rates the model on the frames it left
# out (fit-eval --frames odd).
# --ceiling N rates each fit against the ceiling of the true ghosts above N noise σ, the rest
# drawn as the model's quadratic pedestal (fit-ceiling --fit-above N --quadratic-pedestal: what a
# fitter that found those ghosts could reach; 0: every ghost, the model's ceiling), measured on
# every 4th frame (the frames a fit fits, 0.8° apart; with --holdout every 5th, whose odd ones are
# rated) and kept in DIR/ceilings.
# Captures are kept in DIR/captures/<lens>-640-s<seed>: simulating one takes 3–20 min, a fit
# 0.5–10 min on 2 cores. Needs jq.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
lenses="heliar tessar tessar-rggb nikon"
seeds="1 2 3"
lambdas="0.98 0.99 1 1.01 1.02"
out=${TMPDIR:-/tmp}/flarekit-fit-accuracy
flarekit=$here/build/bin/flarekit
holdout=0
eval_only=0
ceiling=
while (($#)); do
  case $1 in
    --lenses) lenses=$2; shift 2 ;;
    --lambdas) lambdas=$2; shift 2 ;;
    --seeds) seeds=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --flarekit) flarekit=$2; shift 2 ;;
    --holdout) holdout=1; shift ;;
    --ceiling) ceiling=$2; shift 2 ;;
    --eval-only) eval_only=1; shift ;;
    --) shift; break ;;
    *) echo "fit_accuracy.sh: unknown option $1 (see the comment at the top)" >&2; exit 2 ;;
  esac
done
command -v jq >/dev/null || { echo "fit_accuracy.sh: needs jq (scripts/setup.sh installs it)" >&2; exit 1; }
[[ -x $flarekit ]] || { echo "fit_accuracy.sh: $flarekit not built (run scripts/setup.sh)" >&2; exit 1; }

eval_args=()
((holdout)) && eval_args=(--frames odd)
# One line of figures from a fit-eval JSON: recall % precision % PSNR dB centroid px centroid %
# flux error % continuity, gap to the ceiling dB (null, where fit-eval has none, as nan).
columns=8
figures() {
  jq -r 'def pct: if . == null then null else 100 * . end;
         [(.recall | pct), (.precision | pct), .median_psnr_db, .median_centroid_error_px,
          .median_centroid_error_pct, (.median_flux_error | pct), .continuity,
          .median_ceiling_gap_db]
         | map(if . == null then "nan" else . end) | @tsv' "$1"
}

echo "recall % / precision % / median PSNR dB / median centroid error px / median centroid error %" \
  "of radius / median flux error % / continuity / median gap to the ceiling dB (fit-eval against" \
  "the truth)"
for lens in $lenses; do
  rows=()
  for seed in $seeds; do
    capture=$out/captures/$lens-640-s$seed
    if [[ ! -f $capture/manifest.json ]] || ! jq -e '.status == "complete"' "$capture/manifest.json" >/dev/null; then
      echo "simulating $capture"
      mkdir -p "$out/captures"
      rig=$out/captures/sim-$lens-640-s$seed.toml
      sed "s/^seed = .*/seed = $seed/" "$here/tests/data/fit/sim-$lens-640.toml" >"$rig"
      resume=()
      [[ -d $capture ]] && resume=(--resume)
      "$flarekit" -q capture --rig "$rig" --out "$capture" --from 0 --to 30 --step 0.2 "${resume[@]}"
    fi
    ceiling_args=()
    if [[ -n $ceiling ]]; then
      every=4
      ((holdout)) && every=5
      ceiling_file=$out/ceilings/$lens-640-s$seed-above$ceiling-every$every.json
      if [[ ! -f $ceiling_file ]]; then
        mkdir -p "$out/ceilings"
        above=()
        [[ $ceiling != 0 ]] && above=(--fit-above "$ceiling" --quadratic-pedestal)
        "$flarekit" -q fit-ceiling "$capture" --every "$every" --json "${above[@]}" >"$ceiling_file.tmp"
        mv "$ceiling_file.tmp" "$ceiling_file"
      fi
      ceiling_args=(--ceiling "$ceiling_file")
    fi
    for lambda in $lambdas; do
      run=$out/$lens-s$seed-$lambda
      ((holdout)) && run+=-holdout
      mkdir -p "$run"
      args=("$capture" --edge-weight "$lambda" --out "$run/model.json" --report "$run/report")
      ((holdout)) && args+=(--holdout odd)
      ((eval_only)) || "$flarekit" -q fit "${args[@]}" "$@"
      "$flarekit" -q fit-eval "$run/model.json" "$capture" "${eval_args[@]}" "${ceiling_args[@]}" --json \
        >"$run/eval_model.json"
      line="$(figures "$run/eval_model.json")"
      if ((!holdout)); then
        "$flarekit" -q fit-eval "$run/report/frame_fits.json" "$capture" "${ceiling_args[@]}" --json \
          >"$run/eval_frames.json"
        line+=$'\t'"$(figures "$run/eval_frames.json")"
      fi
      seconds=$(jq -r '.seconds_total | . * 10 | round / 10' "$run/report/summary.json")
      awk -v head="$lens seed $seed λ×$lambda" -v seconds="$seconds" -v m="$columns" '
        function part(from,    k, t) {
          for (k = 0; k < m; ++k) t = t (k ? "/" : "") ($(from + k) == "nan" ? "–" : sprintf(k == 6 ? "%.2f" : "%.1f", $(from + k)))
          return t
        }
        {
          printf "%s: model %s", head, part(1)
          if (NF > m) printf ", frame fits %s", part(m + 1)
          printf ", %s s\n", seconds
        }' <<<"$line"
      rows+=("$line"$'\t'"$seconds")
    done
  done
  # Mean and range over λ × seeds of each column (model; then the frames' own fits), over the fits
  # that have a value there; the last column is the fit's seconds.
  printf '%s\n' "${rows[@]}" | awk -v lens="$lens" -v n="$(($(wc -w <<<"$lambdas") * $(wc -w <<<"$seeds")))" -v m="$columns" '
    { for (i = 1; i <= NF; ++i) if ($i != "nan") {
        s[i] += $i; ++c[i]; if (!(i in lo) || $i < lo[i]) lo[i] = $i; if (!(i in hi) || $i > hi[i]) hi[i] = $i }
      nf = NF }
    END {
      split("recall % | precision % | PSNR dB | centroid px | centroid % | flux error % | continuity | gap to the ceiling dB", name, " [|] ")
      for (part = 0; part * m < nf - 1; ++part) {
        printf "%s mean over %d fits (λ × seeds), %s: ", lens, n, part == 0 ? "model" : "frame fits"
        for (k = 1; k <= m; ++k) {
          i = part * m + k; f = k == 7 ? "%.2f" : "%.1f"
          if (c[i]) printf "%s " f " (" f "–" f ")", name[k], s[i] / c[i], lo[i], hi[i]
          else printf "%s –", name[k]
          printf(k < m ? ", " : "\n")
        }
      }
      printf "%s seconds per fit: %.1f (%.1f–%.1f)\n", lens, s[nf] / c[nf], lo[nf], hi[nf]
    }'
done
