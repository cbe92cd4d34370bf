#!/usr/bin/env bash
# Rebuild the shipped behavior oracles (docs/enlil.md, "Shipped oracles") from a fresh clone:
# render the datasets, run Enlil's search per model and phenomenon, train one oracle per
# model, and pin each oracle's file and sha256 in examples/models/rover.yaml / uav.yaml.
# The oracles of the rover's Enki models (rover-hsl, rover-raindrop, rover-fog-enki) are made
# with their models by scripts/train-domains.sh; the UAV's domain models' oracles are re-made
# here on both of the UAV's phenomena (train-domains.sh calls this script after it registers
# uav-fog or uav-rain_brightness).
#
#   scripts/train-oracles.sh                 # all five (rover-default, rover-low_light,
#                                            # uav-default, uav-fog, uav-rain_brightness)
#   scripts/train-oracles.sh rover-low_light # only the ones named
#   BUDGET=300 FRAMES=2000 EPOCHS=8 scripts/train-oracles.sh   # quicker, weaker (all models)
#   ARCH_raindrop=patch_cnn scripts/train-oracles.sh rover-default   # another network
#
# The oracle network (`oracle train --architecture`, docs/enlil.md, "Shipped oracles") is
# the measured choice, written once in code (anunnaki.enlil.oracle_architecture, asked
# through `anunnaki oracle architecture --batch`, one line a model; `anunnaki robustify` asks
# it too): the model's own (rover-default patch_cnn, for its false alarms on close
# pedestrians; rover-low_light patch_cnn, kept as shipped), else the one its phenomena name
# (none today: hsl, raindrop and fog tie at the shipped scale), else small_cnn. Variables
# come first: ARCH_<phenomenon> (ARCH_hsl, ARCH_raindrop …; a composition's with + as _:
# ARCH_rain_brightness) names a phenomenon's network (one
# oracle covers all of its model's phenomena: those named must agree; empty, ARCH_hsl=,
# drops a table entry); ARCH_<model> (dashes as underscores: ARCH_rover_default) sets one
# model's network; ARCH the network of a model nothing names. `scripts/train-oracles.sh
# --print-architectures` prints each model's choice and trains nothing. Every model's network
# is asked before anything runs, in one call (one interpreter for all: each start took 3-13 s
# when it imported torch): a conflict stops the script before its first step.
# Without BUDGET/FRAMES/EPOCHS each model gets the settings its shipped oracle was made with
# (the table at the end; docs/enlil.md): the shipped files are rebuilt with the same settings.
# Every step's wall time goes to $RUNS/times.tsv. Assessments resume when re-run (the
# archives are in $RUNS); datasets are rendered once. Two threads / two workers: the
# machine this was written on has two cores.
set -euo pipefail
cd "$(dirname "$0")/.."

PY=${PY:-.venv/bin/python}
DATA=${DATA:-data}
RUNS=${RUNS:-runs/oracles}
THREADS=${THREADS:-2}
SEED=${SEED:-0}
MODELS=${MODELS:-examples/models} # a scratch copy keeps the shipped files (and their pins) as they are
ANUNNAKI=("$PY" -m anunnaki.cli.main)

PRINT_ARCH=0
if [[ ${1:-} == --print-architectures ]]; then
  PRINT_ARCH=1
  shift
fi
TIMES="$RUNS/times.tsv"
# Two passes over the models (oracles, below): plan lists each model's oracle (its
# `oracle architecture` line) and does nothing else; run trains them (or, with
# --print-architectures, prints each model's network).
STAGE=plan

timed() { # timed NAME COMMAND...: run it, append its wall seconds to $TIMES
  local name=$1 start=$SECONDS
  shift
  echo "==> $name" >&2
  "$@"
  printf '%s\t%d\n' "$name" $((SECONDS - start)) >> "$TIMES"
}

dataset() { # dataset NAME [make-dataset options]: NAME is the platform, or rover-open
  local name=$1
  shift
  if [[ $STAGE == run && $PRINT_ARCH == 0 && ! -f $DATA/$name/val.json ]]; then
    timed "make-dataset $name" "${ANUNNAKI[@]}" make-dataset "${name%-open}" \
      --out "$DATA/$name" --workers "$THREADS" "$@"
  fi
}

ASSESS=() # more `assess` options for the next train's archives (the UAV's Enki models: 16 images)
TAG=""    # appended to the next train's archive folders ($RUNS/MODEL-PHENOMENON$TAG)

assess() { # assess MODEL PLATFORM PHENOMENON BUDGET: one Enlil archive
  local model=$1 platform=$2 phenomenon=$3 budget=$4
  timed "assess $model $phenomenon" "${ANUNNAKI[@]}" assess "$MODELS/$model.safetensors" \
    --data "$DATA/$platform" --phenomenon "$phenomenon" --budget "$budget" --seed "$SEED" \
    --workers "$THREADS" "${ASSESS[@]}" --out "$RUNS/$model-$phenomenon$TAG" --json \
    > "$RUNS/$model-$phenomenon$TAG.json"
}

EXTRA=() # more `oracle train` options for the next train (rover-default: --extra-data)

PLANNED=() # the models, in order
ASK=()     # one `oracle architecture --batch` line a model (none for one ARCH_<model> names)
ARCHS=""   # the answers: "MODEL<tab>NETWORK" a line
plan_architecture() { # plan_architecture MODEL PHENOMENON...: how to choose MODEL's network
  local model=$1 own="ARCH_${1//-/_}" phenomenon var line
  shift
  PLANNED+=("$model")
  if [[ -n ${!own:-} ]]; then
    ARCHS+="$model"$'\t'"${!own}"$'\n'
    return
  fi
  line=$(printf '%q ' "$@" --model "$model")
  line=${line% }
  for phenomenon in "$@"; do
    var="ARCH_${phenomenon//+/_}" # a composition's: ARCH_rain_brightness for rain+brightness
    if [[ -n ${!var+set} ]]; then line+=$(printf ' --choose %q' "$phenomenon=${!var}"); fi
  done
  ASK+=("$line")
}

ask_architectures() { # every planned model's network, in one interpreter (the rule is in code)
  local rows="" model
  if ((${#ASK[@]})); then
    # the first line that fails stops the answers (its error is on stderr, above)
    rows=$(printf '%s\n' "${ASK[@]}" |
      "${ANUNNAKI[@]}" oracle architecture --batch --default "${ARCH:-small_cnn}") || true
  fi
  ARCHS+=$rows$'\n'
  for model in "${PLANNED[@]}"; do
    if [[ -z $(arch_of "$model") ]]; then
      echo "train-oracles.sh: no oracle network for $model (above): set ARCH_${model//-/_} to the one to train" >&2
      return 1
    fi
  done
}

arch_of() { # arch_of MODEL: its network from the answers (empty: none)
  local model arch
  while IFS=$'\t' read -r model arch; do
    if [[ $model == "$1" ]]; then
      echo "$arch"
      return
    fi
  done <<< "$ARCHS"
}

train() { # train MODEL PLATFORM REGISTRY BUDGET FRAMES EPOCHS PHENOMENON...
  local model=$1 platform=$2 registry=$3 budget=${BUDGET:-$4} frames=${FRAMES:-$5}
  local epochs=${EPOCHS:-$6} arch
  shift 6
  if [[ $STAGE == plan ]]; then
    plan_architecture "$model" "$@"
    return
  fi
  arch=$(arch_of "$model")
  if [[ $PRINT_ARCH == 1 ]]; then
    printf '%s\t%s\n' "$model" "$arch"
    return
  fi
  local archives=()
  for phenomenon in "$@"; do
    assess "$model" "$platform" "$phenomenon" "$budget"
    archives+=(--archive "$RUNS/$model-$phenomenon$TAG")
  done
  timed "oracle train $model" "${ANUNNAKI[@]}" oracle train --models "$registry" \
    --model "$model" --data "$DATA/$platform" "${archives[@]}" \
    --out "$MODELS/$model.oracle" --frames "$frames" --epochs "$epochs" --seed "$SEED" \
    --architecture "$arch" --threads "$THREADS" "${EXTRA[@]}" --json > "$RUNS/$model.oracle.json"
  "$PY" scripts/pin-oracle.py "$registry" "$model" "$MODELS/$model.oracle.safetensors"
}

DOMAINS=${DOMAINS:-runs/domains}
domain_oracle() { # domain_oracle ID OWN OTHER: ID's oracle on its phenomenon OWN and OTHER
  local id=$1 own=$2
  if [[ $STAGE == run && $PRINT_ARCH == 0 && -z $TAG && ! -e $RUNS/$id-$own && -d $DOMAINS/$id/assess ]]; then
    cp -r "$DOMAINS/$id/assess" "$RUNS/$id-$own"
  fi
  train "$id" uav "$MODELS/uav.yaml" 96 1500 8 "$own" "$3"
  [[ $STAGE == plan || $PRINT_ARCH == 1 ]] || "$PY" scripts/describe-domain.py "$MODELS/uav.yaml" "$id"
}

SELECTED=" $* "
pick() { [[ $SELECTED == "  " || $SELECTED == *" $1 "* ]]; } # no names: all of them

oracles() { # the models' oracles (one pass: STAGE above)
  # rover-default: the phenomena of the issue (hsl, raindrop, fog) and brightness, the demo's dusk
  if pick rover-default || pick rover-low_light; then dataset rover; fi
  # ... and, among its frames, bare-ground scenes (no clutter): the look of the demo's
  # background: false (docs/enlil.md, "In the loop", its false alarm)
  if pick rover-default; then
    dataset rover-open --no-clutter --per-layout 10 --test-layouts ""
    EXTRA=(--extra-data "$DATA/rover-open")
  fi
  #                                                    budget frames epochs phenomena
  pick rover-default && train rover-default rover "$MODELS/rover.yaml" 600 3000 12 \
    hsl raindrop fog brightness
  EXTRA=()
  # the --augment domain model, on the phenomena it was fine-tuned for (docs/detector.md)
  pick rover-low_light && train rover-low_light rover "$MODELS/rover.yaml" 400 3000 12 brightness hsl
  if pick uav-default || pick uav-fog || pick uav-rain_brightness; then
    dataset uav --width 320 --height 240
  fi
  # 176 evaluations (11 rounds) per phenomenon: the first shipped one's search was stopped
  # there for time. fog and rain+brightness: the UAV's domain models (uav-fog,
  # uav-rain_brightness, docs/robustify.md) are swapped in when this oracle names their domain.
  pick uav-default && train uav-default uav "$MODELS/uav.yaml" 176 2000 10 fog rain+brightness
  # The UAV's Enki models (scripts/train-domains.sh makes them, each with an oracle of its own
  # phenomenon only): their oracles learn both of the platform's phenomena, as uav-default's,
  # so that the active model's oracle names the next condition (the demo flies from
  # rain+brightness into fog, docs/uav.md). The settings of their chains' own assessment and
  # oracle: 96 evaluations of 16 images; 1,500 frames x 8 epochs. The archive of the model's
  # own phenomenon is the same search as its chain's assess stage: when $DOMAINS/ID/assess
  # exists (train-domains.sh's work folder), it is copied rather than run again, unless the
  # oracle is assessed through the camera's encoding (a $TAG, below), which that search was not.
  # describe-domain.py then writes the new oracle's val figures into the entry's description.
  # The UAV's camera sends JPEG at quality 90 (examples/uav/demo-scenario.yaml): uav-fog's
  # oracle is assessed and trained through it (assess --encoding; oracle train follows the
  # archives), for in fog the JPEG costs uav-fog more F1 than the fog alone (docs/uav.md, "The
  # oracle against the ground truth"). Its archives are searched in folders of their own
  # ($RUNS/uav-fog-fog-jpeg90 …): one assessed without the encoding does not resume into them.
  ASSESS=(--batch-images 16 --encoding jpeg:90)
  TAG=-jpeg90
  pick uav-fog && domain_oracle uav-fog fog rain+brightness
  ASSESS=(--batch-images 16)
  TAG=""
  pick uav-rain_brightness && domain_oracle uav-rain_brightness rain+brightness fog
  ASSESS=()
}

oracles
ask_architectures
STAGE=run
if [[ $PRINT_ARCH == 0 ]]; then
  mkdir -p "$RUNS"
  [[ -f $TIMES ]] || printf 'step\tseconds\n' > "$TIMES"
fi
oracles
[[ $PRINT_ARCH == 1 ]] || echo "times: $TIMES" >&2
