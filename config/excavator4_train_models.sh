#!/usr/bin/env bash
# Rebuilds the whole machine's shipped per-loop models config/{boom,stick,bucket,swing}_
# excavator4.model.npz from simulated normal operation of the whole machine
# (config/excavator4_sim.yaml): patterns from 6 x 600 s of mixed duty cycles (seeds
# 101-106) and 4 x 600 s of lifting (seeds 107-110), thresholds from 12 x 600 s of mixed work
# and 4 x 600 s of lifting more, held out (seeds 201-212, 213-216): eps0 = 2 x max normal J
# (N = 3000), b0 = 2 x max normal B.  Four hours and twenty minutes in all.  The lifting
# runs are there for the long holds of a hung load: mixed work lifts now and then, each run
# at its own oil temperature, so an hour of it held a light load (60-70 bar on the boom's
# cap side) in one run only, at 54 degC, and a GRNN whose nearest patterns at that pressure and
# temperature are the load being hung (PA moving with every spool closed) predicts a held
# load falling: B rose in long holds (docs/benchmarks.md, "Long holds of a hung load").  Two
# held-out runs were too few for B: rare normal holds (such as a pressure trapped by a rod
# run into its end stop) that 20 minutes missed put B far above a threshold set without
# them.  Each loop on the `section` preset (PP and the other loops' spool commands as
# inputs: config/excavator4.yaml declares one load-sensing pump), no fault signatures (the
# boom simulator has no neighbours); J leaves the samples settling on an end stop out (the
# default of `monitor train`).  17-18 minutes a loop wall-clock (measured with the four run in parallel at a
# load average of 25-28 on 2 cores; the GRNN fit 5-8 minutes of it).
# The stick's patterns add 2 x 600 s of the `dig-lift` training cycle (seeds 111-112: truck
# loading whose lift starts at every phase of the stick's dig move's end).  Mixed work brings
# the boom's lift ramp onto a stick still open at 60-100 % about 2.5 times an hour for
# 0.1-0.2 s, so the fit held three such events, all of them the stick's pressures collapsing
# as its spool closed, and the stick's model predicted that collapse where the stick had not
# yet closed: B alarmed on 2 of 48 normal runs (docs/benchmarks.md, "Why the retrained
# stick's bias statistic alarms").  The boom, bucket and swing models were built without those
# two runs (their patterns and every loop's thresholds come from the same runs as before), so
# the script rebuilds all four files as shipped.
# The swing's patterns add 4 x 600 s of the `return-to-stop` training cycle (seeds 113-116:
# truck loading whose return sets the boom down onto its bottom stop as the swing brakes).
# A boom stalled on its stop starves the swing's meter-in as its spool closes, and the motor
# traps 72-76 bar (in the 100 minutes of mixed work and lifting fitted, 71.5 bar once): the
# swing's model predicted the trapped pressures drifting apart at rest there, and B
# alarmed on a normal run (docs/benchmarks.md, "The swing trained on a boom set down on its
# stop").  The boom, stick and bucket models are built without those runs.
# The boom's patterns add 6 x 600 s of the `rest-on-stop` training cycle (seeds 117-122:
# truck loading whose return lowers the boom onto its bottom stop, the lever let go around
# the simulated landing).  A boom resting on its stop keeps on its rod side whatever was
# there when the spool closed, from the lowering pressure to the stall; mixed work leaves
# 15-70 bar there now and then, which the 100 minutes fitted held for 9 s with a neighbour
# working, and the boom's model predicted its cap side rising 5-12 bar a step when the bucket
# opened: B alarmed on 4 runs of 100 h (docs/benchmarks.md, "The boom at rest on its
# stop").  Its thresholds rest on 4 x 600 s of lifting more (seeds 217-220 of `lifting`,
# held out for the boom only; the stick's 217-220 below are `dig-lift` runs): the retrained boom's B on the 16 runs held out peaked on one lifting run's hung
# load at 2.3 x every other run, and the support rule's transfer check (1.18 x) switched B
# off; its L is fitted on the 16 runs as before (benchmarks/excavator4_add_lever.py after
# this script), where with 20 its transfer check (2.04 x) would switch it off.
# The swing's patterns add 4 x 600 s of mixed work on oil at 59-61.5 degC (seeds 646, 703,
# 810, 854, chosen for their oil), and its pattern budget is 8000: the simulator's oil runs
# to 62 degC, the runs fitted to 59.8, and the swing at rest on hotter oil was predicted
# drifting (B up to 1.18 x b0 on 100 h, every run above 0.95 x at 59-61.6 degC).  At 6000
# patterns the added runs coarsened the swing's other rests (74.8 bar on 40.8 degC oil
# predicted drifting 0.46 bar a step).
# `monitor train` fits the full-lever statistic L on each loop's flow QP (a shortfall at full
# lever: a stroke limit); on the held-out runs 201-216 it earns its threshold on the boom,
# bucket and swing (as retrained with return-to-stop), not the stick (never lowered at full
# lever for 3 s).  The shipped bucket, boom and swing files carry it (added to the shipped
# networks on those runs by benchmarks/excavator4_add_lever.py, as this script fits it).
# The stick's L (raising only: lowering at full lever its flow is never short of the
# model's prediction) rests on 44 more held-out runs, the stick's alone: seeds 217-220 of
# `dig-lift` and 221-260 of mixed work, as held_stick_SEED.csv beside the runs above,
#   python benchmarks/excavator4_add_lever.py HELD OUT --loops stick
# (on 201-216 alone the stick at full lever beside the bucket at full lever, the pump's
# whole flow, left it 0.095 z short once, and its threshold did not carry between halves).
# Not given to `monitor train` here: its J and B would be refitted on them too, and on
# dig-lift seed 220 at 8.0 min the stick's J reaches 4.2 x its eps0 (B 11 x).
# The bucket's model predicts its rod's speed too (`--rod-speed`: RodSpeed, from
# Bucket_RodPos over 0.1 s, a fourth output), and its L watches that speed's shortfall at
# full lever instead of the flow's: a piston leak slows the rod for the same section flow,
# which the flow and the pressures hardly show (its piston wear at 0.5 was found on 0 of 4
# runs of seed sets 9-12); a stroke limit slows it as it cuts the flow.
#   bash config/excavator4_train_models.sh
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
seq 101 106 | xargs -P "$(nproc)" -I{} monitor simulate --machine excavator4 --duration 600 \
  --seed {} --out "$work/fit_{}.csv" >/dev/null
seq 107 110 | xargs -P "$(nproc)" -I{} monitor simulate --machine excavator4 --duration 600 \
  --cycle lifting --seed {} --out "$work/fit_{}.csv" >/dev/null
seq 111 112 | xargs -P "$(nproc)" -I{} monitor simulate --machine excavator4 --duration 600 \
  --cycle dig-lift --seed {} --out "$work/fit_{}.csv" >/dev/null
seq 113 116 | xargs -P "$(nproc)" -I{} monitor simulate --machine excavator4 --duration 600 \
  --cycle return-to-stop --seed {} --out "$work/fit_{}.csv" >/dev/null
seq 117 122 | xargs -P "$(nproc)" -I{} monitor simulate --machine excavator4 --duration 600 \
  --cycle rest-on-stop --seed {} --out "$work/fit_{}.csv" >/dev/null
printf '%s\n' 646 703 810 854 | xargs -P "$(nproc)" -I{} monitor simulate --machine excavator4 \
  --duration 600 --seed {} --out "$work/hot_{}.csv" >/dev/null
seq 201 212 | xargs -P "$(nproc)" -I{} monitor simulate --machine excavator4 --duration 600 \
  --seed {} --out "$work/held_{}.csv" >/dev/null
seq 213 220 | xargs -P "$(nproc)" -I{} monitor simulate --machine excavator4 --duration 600 \
  --cycle lifting --seed {} --out "$work/held_{}.csv" >/dev/null
# --fault-check off: simulated normal operation by construction.
for loop in boom stick bucket swing; do
  fit=("$work"/fit_{101..110}.csv)
  held=("$work"/held_{201..216}.csv)
  patterns=()
  if [ "$loop" = boom ]; then fit+=("$work"/fit_{117..122}.csv); held+=("$work"/held_{217..220}.csv); fi
  if [ "$loop" = stick ]; then fit+=("$work"/fit_{111..112}.csv); fi
  if [ "$loop" = bucket ]; then patterns=(--rod-speed); fi
  if [ "$loop" = swing ]; then
    fit+=("$work"/fit_{113..116}.csv "$work"/hot_{646,703,810,854}.csv)
    patterns=(--max-patterns 8000)
  fi
  monitor train "${fit[@]}" --held-out "${held[@]}" "${patterns[@]}" \
    --loop "$loop" --config "$here/excavator4.yaml" --fault-check off \
    --out "$here/${loop}_excavator4.model.npz"
done
# The boom's L on the 16 runs the others' thresholds rest on (see above).
mkdir "$work/held16" "$work/lever"
ln -s "$work"/held_{201..216}.csv "$work/held16/"
python "$here/../benchmarks/excavator4_add_lever.py" "$work/held16" "$work/lever" --loops boom \
  >/dev/null
cp "$work/lever/boom_excavator4.model.npz" "$here/"
