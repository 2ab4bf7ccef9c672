#!/usr/bin/env bash
# Re-make every number and figure of docs/analysis.md: runs holonomic-analyze
# for each, writes the figures into docs/analysis/ and the printed output into
# docs/analysis/output.txt (each command above its output). About a minute.
# Usage: scripts/analysis_docs.sh   (after `make setup`)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
set +u; . ros2_ws/env.sh; set -u
OUT=docs/analysis
mkdir -p "$OUT"
LOG="$OUT/output.txt"
: > "$LOG"
run() {
    echo "\$ $*" | tee -a "$LOG"
    "$@" 2>&1 | grep -v '^pybullet build time' | tee -a "$LOG"
    echo | tee -a "$LOG"
}
PAPER=(-p robot.name:=ddrot_r1a1b1 -p ddrot.wheel_radius:=1 -p ddrot.half_wheel_separation:=1
       -p ddrot.turret_offset:=1 -p joints.left_wheel_joint.max_velocity:=1
       -p joints.right_wheel_joint.max_velocity:=1 -p joints.turret_joint.max_velocity:=1)
# mobility ellipsoid, H_hat and the design sweeps (Costa & Yim)
run holonomic-analyze hamr --plot "$OUT" --sweep ddrot.turret_offset=0.05:0.4:8 \
    --sweep ddrot.wheel_radius=0.03:0.09:7 --sweep joints.turret_joint.max_velocity=2:12:6
run holonomic-analyze hamr "${PAPER[@]}" --plot "$OUT"
run holonomic-analyze xr4000 --plot "$OUT" --isotropy --trajectory
run holonomic-analyze xr4000 --steer 0.785398,2.356194,-2.356194,-0.785398 --isotropy
# caster isotropy (Kim & Moon) on the three-caster robot
run holonomic-analyze comr3 --plot "$OUT" --isotropy --isotropic-search --trajectory
run holonomic-analyze comr3 -p pcv.caster_offset:=0.04 -p pcv.wheel_radius:=0.04 --isotropic-search
run holonomic-analyze comr3 -p pcv.caster_offset:=0.062354 -p pcv.wheel_radius:=0.077942 \
    --isotropic-search
# measured holonomicity: kinematic limit, d_T shrinking
for d in 1.0 0.3 0.1 0.03; do
    run holonomic-analyze hamr --measure --kinematic --distance "$d"
done
run holonomic-analyze xr4000 --measure --kinematic
run holonomic-analyze comr3 --measure --kinematic
# measured holonomicity in the simulator (ideal velocity motors instead of the drive model), the configured limits
run holonomic-analyze hamr --measure -p sim.ideal_motors:=true --heading-changes 0,1.570796,-1.570796,3.141593 --plot "$OUT"
run holonomic-analyze xr4000 --measure -p sim.ideal_motors:=true --heading-changes 0,1.570796,-1.570796,3.141593 --plot "$OUT"
run holonomic-analyze comr3 --measure -p sim.ideal_motors:=true --heading-changes 0,1.570796,-1.570796,3.141593 --plot "$OUT"
# the three families side by side: H and the time to reverse at speed
run python -m holonomic_analysis.family_comparison hamr xr4000 swerve4 --driver sim -p sim.ideal_motors:=true
run python -m holonomic_analysis.family_comparison hamr xr4000 swerve4 --driver sim -p sim.ideal_motors:=true \
    -p limits.linear.x.max_acceleration:=1.0 -p limits.linear.y.max_acceleration:=1.0 \
    -p limits.linear.x.max_deceleration:=1.5 -p limits.linear.y.max_deceleration:=1.5 \
    -p limits.linear.x.max_velocity:=1.2 -p limits.linear.y.max_velocity:=1.2
# the swerve's static numbers: reoriented speeds, and the mobility at a configuration
run holonomic-analyze swerve4
run holonomic-analyze swerve4 --steer 1.570796,1.570796,1.570796,1.570796
run holonomic-analyze swerve4 --steer 2.356194,-2.356194,-0.785398,0.785398
run holonomic-analyze swerve4 --steer 0.3,0,0,0
for d in 1.0 0.1 0.01; do
    run holonomic-analyze swerve4 --measure --kinematic --directions 4 --distance "$d"
done
