#!/usr/bin/env bash
# Frames per second of the real-time viewer (`flarekit view`, issue 9) in headless Chromium: the
# page's own #bench=N mode draws N frames across the model's angle range, each finished
# (read back) before the next, at the window's size. Measured for MODEL and for a synthetic model
# of --ghosts ghosts made from MODEL's (copied round-robin, each moved by a few pixels so that no
# two coincide), the many-ghost case a zoom lens gives.
#
#   bench/view_fps.sh [--model MODEL] [--ghosts 100] [--frames 30] [--size 1280x720]
#                     [--flarekit BIN] [--gpu]
#
# Chromium draws WebGL2 on SwiftShader (software, on the CPU) unless --gpu is given; the renderer
# it used is printed with each figure. Needs chromium and jq.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
model=$here/tests/data/view/demo_model.json
ghosts=100
frames=30
size=1280x720
flarekit=$here/build/bin/flarekit
angle=(--use-angle=swiftshader --enable-unsafe-swiftshader)
while (($#)); do
  case $1 in
    --model) model=$2; shift 2 ;;
    --ghosts) ghosts=$2; shift 2 ;;
    --frames) frames=$2; shift 2 ;;
    --size) size=$2; shift 2 ;;
    --flarekit) flarekit=$2; shift 2 ;;
    --gpu) angle=(); shift ;;
    *) echo "view_fps.sh: unknown option $1" >&2; exit 2 ;;
  esac
done

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# The synthetic model: MODEL's ghosts repeated to the count, ghost k moved by k px along x and y.
jq --argjson n "$ghosts" '
  .ghosts as $g | ($g | length) as $m |
  .ghosts = [range($n) as $k | $g[$k % $m] | .id = $k |
             .parameters.Mx[0] += (($k % 17) - 8) * 3 | .parameters.My[0] += (($k % 13) - 6) * 2]' \
  "$model" > "$work/many.json"

for m in "$model" "$work/many.json"; do
  "$flarekit" -q view "$m" --out "$work/view.html" > /dev/null
  result=$(chromium --headless --no-sandbox --disable-gpu --no-first-run --disable-background-networking \
             --user-data-dir="$work/profile" "${angle[@]}" --window-size="${size/x/,}" --hide-scrollbars \
             --dump-dom "file://$work/view.html#ui=0&size=$size&bench=$frames" 2> /dev/null |
           sed -n 's:.*<pre id="bench">\(.*\)</pre>.*:\1:p')
  [[ -n $result ]] || { echo "view_fps.sh: the page reported no figure for $m" >&2; exit 1; }
  name=$([[ $m == "$model" ]] && echo "$model" || echo "synthetic, $ghosts ghosts")
  jq -c --arg model "$name" '{model: $model} + .' <<< "$result"
done
