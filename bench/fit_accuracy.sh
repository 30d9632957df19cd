#!/usr/bin/env bash
# The fit's acceptance figures (issue 6) on the simulated 640×427 captures, and their spread.
#
# For each lens (tests/data/fit/sim-<lens>-640.toml, 0–30° at 0.2°, simulated on first use) and
# each edge weight λ, fits the capture with a report, then rates the model and the report's
# per-frame fits against the ground truth with fit-eval. Prints one line per fit and, per lens,
# the mean and the range over the λ of recall / precision / median PSNR / median centroid error
# (px, and % of the ghost's radius) / median flux error / continuity.
#
# Why several λ: the fitter's discrete decisions (a detection kept or not, a track ended a frame
# sooner) amplify small changes, and λ × 0.99 against λ × 1.01 moves one lens's recall by 10
# points or more. One fit cannot tell a change from that spread; the mean over λ, set against its
# range, can tell only changes larger than it.
#
#   bench/fit_accuracy.sh [--lenses "heliar tessar"] [--lambdas "0.99 1 1.01"] [--holdout]
#                         [--out DIR] [--flarekit BIN] [--eval-only] [-- more flarekit fit options]
#
# --eval-only rates the fits already in DIR again (after a change to fit-eval) without fitting.
# --holdout fits every other frame (fit --holdout odd) and rates the model on the frames it left
# out (fit-eval --frames odd). A fit takes 1–2 min on 2 cores. Needs jq.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
lenses="heliar tessar"
lambdas="0.99 1 1.01"
out=${TMPDIR:-/tmp}/flarekit-fit-accuracy
flarekit=$here/build/bin/flarekit
holdout=0
eval_only=0
while (($#)); do
  case $1 in
    --lenses) lenses=$2; shift 2 ;;
    --lambdas) lambdas=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --flarekit) flarekit=$2; shift 2 ;;
    --holdout) holdout=1; shift ;;
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
# flux error % continuity (null, where fit-eval has none, as nan).
columns=7
figures() {
  jq -r 'def pct: if . == null then null else 100 * . end;
         [(.recall | pct), (.precision | pct), .median_psnr_db, .median_centroid_error_px,
          .median_centroid_error_pct, (.median_flux_error | pct), .continuity]
         | map(if . == null then "nan" else . end) | @tsv' "$1"
}

echo "recall % / precision % / median PSNR dB / median centroid error px / median centroid error %" \
  "of radius / median flux error % / continuity (fit-eval against the truth)"
for lens in $lenses; do
  capture=$out/captures/$lens-640
  if [[ ! -f $capture/manifest.json ]]; then
    echo "simulating $capture"
    "$flarekit" -q capture --rig "$here/tests/data/fit/sim-$lens-640.toml" --out "$capture" --from 0 --to 30 --step 0.2
  fi
  rows=()
  for lambda in $lambdas; do
    run=$out/$lens-$lambda
    ((holdout)) && run+=-holdout
    mkdir -p "$run"
    args=("$capture" --edge-weight "$lambda" --out "$run/model.json" --report "$run/report")
    ((holdout)) && args+=(--holdout odd)
    ((eval_only)) || "$flarekit" -q fit "${args[@]}" "$@"
    "$flarekit" -q fit-eval "$run/model.json" "$capture" "${eval_args[@]}" --json >"$run/eval_model.json"
    line="$(figures "$run/eval_model.json")"
    if ((!holdout)); then
      "$flarekit" -q fit-eval "$run/report/frame_fits.json" "$capture" --json >"$run/eval_frames.json"
      line+=$'\t'"$(figures "$run/eval_frames.json")"
    fi
    seconds=$(jq -r '.seconds_total | . * 10 | round / 10' "$run/report/summary.json")
    awk -v head="$lens λ×$lambda" -v seconds="$seconds" -v m="$columns" '
      function part(from,    k, t) {
        for (k = 0; k < m; ++k) t = t (k ? "/" : "") ($(from + k) == "nan" ? "–" : sprintf(k == m - 1 ? "%.2f" : "%.1f", $(from + k)))
        return t
      }
      {
        printf "%s: model %s", head, part(1)
        if (NF > m) printf ", frame fits %s", part(m + 1)
        printf ", %s s\n", seconds
      }' <<<"$line"
    rows+=("$line")
  done
  # Mean and range over the λ of each column (model; then the frames' own fits), over the fits
  # that have a value there.
  printf '%s\n' "${rows[@]}" | awk -v lens="$lens" -v n="$(wc -w <<<"$lambdas")" -v m="$columns" '
    { for (i = 1; i <= NF; ++i) if ($i != "nan") {
        s[i] += $i; ++c[i]; if (!(i in lo) || $i < lo[i]) lo[i] = $i; if (!(i in hi) || $i > hi[i]) hi[i] = $i } }
    END {
      split("recall % | precision % | PSNR dB | centroid px | centroid % | flux error % | continuity", name, " [|] ")
      for (part = 0; part * m < NF; ++part) {
        printf "%s mean over %d λ, %s: ", lens, n, part == 0 ? "model" : "frame fits"
        for (k = 1; k <= m; ++k) {
          i = part * m + k; f = k == m ? "%.2f" : "%.1f"
          if (c[i]) printf "%s " f " (" f "–" f ")", name[k], s[i] / c[i], lo[i], hi[i]
          else printf "%s –", name[k]
          printf(k < m ? ", " : "\n")
        }
      }
    }'
done
