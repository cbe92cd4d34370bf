#!/usr/bin/env bash
# Rebuild the shipped Enki domain models (docs/robustify.md, "Shipped domain models") from a
# fresh clone: render the datasets, then run `anunnaki robustify` once per domain (Enlil's
# search against the default model, the selection, the fine-tune, the measurement, the new
# model's assessment and its oracle) and register the model and its oracle, with their
# sha256, in examples/models/rover.yaml / uav.yaml.
#
#   scripts/train-domains.sh                          # all five, in the order below
#   scripts/train-domains.sh rover-hsl uav-fog        # only the ones named
#   MODELS=/tmp/models scripts/train-domains.sh       # register into a scratch copy
#   BUDGET=200 EPOCHS=4 scripts/train-domains.sh      # quicker, weaker (all models)
#
# MODELS is the registry folder the chain starts from (rover-default / uav-default) and
# registers into: a scratch copy (cp -r examples/models /tmp/models) keeps the shipped files
# as they are. A model whose id is in the registry already is not trained again (remove its
# entry to rebuild it). Each model's work folder is $RUNS/ID: rerunning after Ctrl-C or
# kill -9 continues where it stopped (the chain's stages, search parts and fine-tune
# checkpoints; docs/robustify.md, "The work folder and resuming"); datasets are rendered once.
# Every step's wall time goes to $RUNS/times.tsv, each chain stage's too (from when its
# stages/NAME.json was written; a stage reused from an earlier run gets no line), with the
# load average when the step started; the chain's messages go to $RUNS/ID.log and its
# summary to $RUNS/ID.summary.json. Two threads / two workers: the machine this was written
# on has two cores.
set -euo pipefail
cd "$(dirname "$0")/.."

PY=${PY:-.venv/bin/python}
DATA=${DATA:-data}
RUNS=${RUNS:-runs/domains}
THREADS=${THREADS:-2}
SEED=${SEED:-0}
MODELS=${MODELS:-examples/models}
ANUNNAKI=("$PY" -m anunnaki.cli.main)

mkdir -p "$RUNS"
TIMES="$RUNS/times.tsv"
[[ -f $TIMES ]] || printf 'step\tseconds\tload average (1 min) at start\n' > "$TIMES"

timed() { # timed NAME COMMAND...: run it, append its wall seconds to $TIMES
  local name=$1 start=$SECONDS load
  shift
  load=$(cut -d' ' -f1 /proc/loadavg 2>/dev/null || echo -)
  echo "==> $name" >&2
  "$@"
  printf '%s\t%d\t%s\n' "$name" $((SECONDS - start)) "$load" >> "$TIMES"
}

dataset() { # dataset PLATFORM [make-dataset options]
  local name=$1
  shift
  if [[ ! -f $DATA/$name/val.json ]]; then
    timed "make-dataset $name" "${ANUNNAKI[@]}" make-dataset "$name" \
      --out "$DATA/$name" --workers "$THREADS" "$@"
  fi
}

registered() { # registered REGISTRY ID: is ID in the registry's models list?
  grep -Eq "^  - id: $2\$" "$1"
}

stage_times() { # stage_times ID: each stage's wall seconds, from its stages/NAME.json
  local id=$1 prev name t
  prev=$(stat -c %Y "$RUNS/$id/robustify.json")
  for name in search select finetune measure assess oracle; do
    [[ -f $RUNS/$id/stages/$name.json ]] || continue
    t=$(stat -c %Y "$RUNS/$id/stages/$name.json")
    ((t >= prev)) || continue
    printf '%s\t%d\t-\n' "  $id: $name" $((t - prev)) >> "$TIMES"
    prev=$t
  done
}

# robustify ID PLATFORM PHENOMENON DOMAIN BUDGET EPOCHS [more robustify options]
robustify() {
  local id=$1 platform=$2 phenomenon=$3 domain=$4 budget=${BUDGET:-$5} epochs=${EPOCHS:-$6}
  local registry="$MODELS/$platform.yaml"
  shift 6
  if registered "$registry" "$id"; then
    echo "train-domains.sh: $id is in $registry already; remove its entry to rebuild it" >&2
    return
  fi
  dataset "$platform" "${DATASET[@]}"
  timed "robustify $id" "${ANUNNAKI[@]}" robustify "$MODELS/$platform-default.safetensors" \
    --data "$DATA/$platform" --phenomenon "$phenomenon" --domain "$domain" --id "$id" \
    --out "$RUNS/$id" --budget "$budget" --epochs "$epochs" --seed "$SEED" \
    --workers "$THREADS" --threads "$THREADS" "$@" --register "$registry" --json \
    > "$RUNS/$id.summary.json" 2>> "$RUNS/$id.log"
  stage_times "$id"
  "$PY" scripts/describe-domain.py "$registry" "$id"
}

SELECTED=" $* "
pick() { [[ $SELECTED == "  " || $SELECTED == *" $1 "* ]]; } # no names: all of them

# The rover: 128x128, `make-dataset rover`'s defaults. hsl moves hue, saturation and
# lightness (not only darkening); raindrop+raindrop+raindrop is one to three drops anywhere
# on the lens (a drop of radius 0 is no drop).
DATASET=()
#                                                                        budget epochs
pick rover-hsl && robustify rover-hsl rover hsl hsl 400 8
pick rover-raindrop && robustify rover-raindrop rover raindrop+raindrop+raindrop raindrop 400 8
# The UAV: 320x240 frames cost about five times the rover's per evaluation and per epoch, so
# its searches are 96 evaluations (6 rounds) of 16 frames each, its fine-tunes 5 epochs, its
# measurement 16 contexts and its oracle 1,500 frames x 8 epochs.
DATASET=(--width 320 --height 240)
UAV=(--batch-images 16 --measure-contexts 16 --oracle-frames 1500 --oracle-epochs 8)
# A chain's oracle knows its own phenomenon only; the shipped ones know both of the UAV's
# (the demo flies from rain+brightness into fog: the active model's oracle must name the
# next condition). So once a chain has registered its model, scripts/train-oracles.sh ID
# re-trains its oracle on the chain's assessment and one of the other phenomenon, pins it
# and rewrites the description (its work folder: $RUNS/oracles).
uav_domain() { # uav_domain ID PHENOMENON DOMAIN: the chain, then its oracle of both phenomena
  local id=$1 fresh=0
  registered "$MODELS/uav.yaml" "$id" || fresh=1
  robustify "$id" uav "$2" "$3" 96 5 "${UAV[@]}"
  if ((fresh)); then
    timed "oracle of both phenomena $id" env DOMAINS="$RUNS" RUNS="$RUNS/oracles" \
      MODELS="$MODELS" DATA="$DATA" PY="$PY" THREADS="$THREADS" SEED="$SEED" \
      scripts/train-oracles.sh "$id"
  fi
}
pick uav-fog && uav_domain uav-fog fog fog
pick uav-rain_brightness && uav_domain uav-rain_brightness rain+brightness rain_brightness
DATASET=()
# rover-fog-enki: the rover's fog model. It replaced rover-fog (`train-detector --augment
# fog`, no longer shipped) as benchmarks/robustify.py measured (docs/enki.md, "Decision").
pick rover-fog-enki && robustify rover-fog-enki rover fog fog 400 8
echo "times: $TIMES" >&2
