"""``holonomic-analyze ROBOT``: the papers' design numbers and figures.

Always: the mobility ellipsoid and speed polytope at one configuration,
``H_hat``, ``sigma_ratio``, the maximum speeds and the orientation bias
(Costa & Yim). On request: design sweeps of any config parameter, caster
isotropy (Kim & Moon) at given steering angles, the search for isotropic
steering configurations, the isotropy index along the demo's scripted
teleop, and the measured holonomicity with the simulator and the controller
in the loop. ``--json`` prints one JSON object; ``--plot DIR`` writes PNGs.

Exit status: 0 on success, 2 on bad arguments or a bad config (one line on
stderr naming the problem).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
import yaml

from holonomic_core.command_line import ArgumentParser, ShowDefaults, number


def _angles(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"comma-separated radians expected, got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"finite comma-separated radians expected, got {text!r}")
    return values


def _param(text: str) -> tuple[str, object]:
    name, sep, value = text.partition(":=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"NAME:=VALUE expected, got {text!r}")
    try:
        return name.strip(), yaml.safe_load(value)
    except yaml.YAMLError:
        raise argparse.ArgumentTypeError(f"unreadable value in {text!r}") from None


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(
        prog="holonomic-analyze", formatter_class=ShowDefaults,
        description="Mobility ellipsoid, holonomicity (theoretical and measured) and caster "
                    "isotropy of a robot config.")
    p.add_argument("robot", help="a config name (hamr, xr4000, comr3) or a robot YAML")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", metavar="DIR", type=Path, help="write the figures (PNG) into DIR")
    p.add_argument("-p", "--param", action="append", type=_param, default=[],
                   metavar="NAME:=VALUE",
                   help="override a config parameter, e.g. -p ddrot.turret_offset:=0.2")
    p.add_argument("--turret", type=number(), metavar="PHI",
                   help="DDROT: turret angle [rad] of the analysed configuration (default 0)")
    p.add_argument("--steer", type=_angles, metavar="PHI1,PHI2,...",
                   help="PCV or swerve: steering angles [rad], one per caster or module, the "
                        "joints' convention "
                        "(the wheel's rolling heading in base_link; default all 0)")
    p.add_argument("--sweep", action="append", default=[], metavar="NAME=START:STOP:N",
                   help="sweep a config parameter (repeatable), e.g. "
                        "ddrot.turret_offset=0.05:0.4:20 or "
                        "joints.turret_joint.max_velocity=2:12:11")
    p.add_argument("--isotropy", action="store_true",
                   help="PCV: isotropy index of Z = B^-1 A at --steer (Kim & Moon)")
    p.add_argument("--isotropic-search", action="store_true",
                   help="PCV: list the isotropic steering configurations of this geometry")
    p.add_argument("--trajectory", action="store_true",
                   help="PCV: isotropy index along the demo's scripted teleop")
    p.add_argument("--measure", action="store_true",
                   help="measured holonomicity: timed moves with the controller in the loop")
    p.add_argument("--driver", choices=("sim", "mock"), default="sim",
                   help="plant for --measure: sim (pybullet) or mock (ideal joints)")
    p.add_argument("--kinematic", action="store_true",
                   help="--measure in the kinematic limit: mock plant, joint speed limits "
                        "only (no twist or acceleration limits)")
    p.add_argument("--distance", type=number(0.0, 100.0, strict_low=True, unit="m"), default=1.0,
                   metavar="D_T", help="--measure: move distance [m] (1 m is the paper's)")
    p.add_argument("--directions", type=number(2, 360, integer=True), default=8,
                   help="--measure: directions, evenly spaced")
    p.add_argument("--heading-changes", type=_angles, default=[0.0], metavar="TH1,TH2,...",
                   help="--measure: heading changes theta_T [rad]")
    args = p.parse_args(argv)
    if args.kinematic:
        args.driver = "mock"
    return args


def _fmt_speeds(speeds: dict) -> str:
    return ", ".join(f"{k} {v:.3f} {'rad/s' if k == 'rotation' else 'm/s'}"
                     for k, v in speeds.items())


def run(args: argparse.Namespace, out=None) -> dict:
    """Compute everything ``args`` asks for; print the report (to ``out``,
    default stdout); return the JSON object."""
    out = sys.stdout if out is None else out
    from holonomic_core.model import load_model
    from holonomic_analysis import holonomicity, isotropy, mobility

    from holonomic_core.config import load_config
    overrides = dict(args.param)
    # The whole configuration, so that a misspelt -p or --sweep key is named
    # (load_model alone reads only the geometry and would ignore it).
    max_speed = load_config(args.robot, overrides).controller.max_speed
    for text in args.sweep:
        key, values = mobility.parse_sweep(text)
        load_config(args.robot, {**overrides, key: float(values[0])})
    model = load_model(args.robot, overrides)

    def positions_of(m):
        return mobility.configuration(m, args.steer, args.turret)

    positions = positions_of(model)
    result = mobility.analyze(model, positions, max_speed)
    report = [f"{model.name} ({model.kind}) at "
              + ", ".join(f"{k} {v:+.3f}" for k, v in result["configuration"].items()
                          if not k.endswith("wheel_joint")),
              f"  H_hat {result['H_hat']:.3f} (constant-heading speed "
              f"{result['constant_heading_speed']['slowest']:.3f} .. "
              f"{result['constant_heading_speed']['fastest']:.3f} m/s)",
              f"  sigma_ratio {result['sigma_ratio']:.4f} (J_joint_to_base, SI units)",
              f"  max speed: {_fmt_speeds(result['max_speed'])}"
              + ("" if result["speed_limit"] is None
                 else f" (limits.linear.max_speed {result['speed_limit']:g} m/s caps them)"),
              f"  orientation bias {result['orientation_bias']:+.3f} rad/m "
              "(skew of the lateral-rotation projection)"]
    if "instantaneous" in result:
        report[1] += " with the wheels reoriented"
        report.append(_instantaneous_line(result["instantaneous"]))
    figures = []
    plot_dir = args.plot
    if plot_dir is not None:
        from holonomic_analysis import plots
        plot_dir.mkdir(parents=True, exist_ok=True)
    if plot_dir is not None and "instantaneous" in result:
        report.append("  (no ellipsoid figures: at a configuration this base's mobility is "
                      f"{result['instantaneous']['mobility_dimension']}-D, the numbers above)")
    elif plot_dir is not None:
        speeds = mobility.SpeedSet.of(model, positions)
        angles = ", ".join(f"{v:+.2f}" for v in positions[_angle_joints(model)])
        title = f"{model.name} at {angles} rad"
        figures.append(plots.mobility_3d(speeds, title,
                                         plot_dir / f"{model.name}_ellipsoid_3d.png"))
        figures.append(plots.mobility_projections(
            speeds, title, plot_dir / f"{model.name}_projections.png"))

    if args.sweep:
        result["sweeps"] = {}
        for text in args.sweep:
            key, values = mobility.parse_sweep(text)
            rows = mobility.sweep(lambda o: load_model(args.robot, o), key, values,
                                  overrides, positions_of, max_speed)
            result["sweeps"][key] = [
                {"value": r["value"], "H_hat": r["H_hat"], "sigma_ratio": r["sigma_ratio"],
                 "max_speed": r["max_speed"], "orientation_bias": r["orientation_bias"]}
                for r in rows]
            report.append(f"sweep of {key}:")
            report.append(f"  {'value':>9s} {'H_hat':>6s} {'fwd':>6s} {'lat':>6s} "
                          f"{'lat@hdg':>7s} {'rot':>6s} {'bias':>7s}")
            for r in rows:
                s = r["max_speed"]
                report.append(f"  {r['value']:9.4g} {r['H_hat']:6.3f} {s['forward']:6.3f} "
                              f"{s['lateral']:6.3f} {s['lateral_constant_heading']:7.3f} "
                              f"{s['rotation']:6.3f} {r['orientation_bias']:+7.3f}")
            if plot_dir is not None:
                figures.append(plots.sweep_plot(rows, key, f"{model.name}: sweep of {key}",
                                                plot_dir / f"{model.name}_sweep_{key}.png"))

    wants_pcv = args.isotropy or args.isotropic_search or args.trajectory
    if wants_pcv and model.kind != "pcv":
        raise ValueError("--isotropy, --isotropic-search and --trajectory are for a "
                         f"powered-caster vehicle; {model.name} is a {model.kind}")
    kin = model.kinematics
    if args.isotropy:
        iso = isotropy.isotropy(kin, positions[0::2])
        result.update({"isotropy_index": iso.index, "L": iso.length,
                       "isotropy": {"c1": iso.c1, "c2": iso.c2,
                                    "isotropic_length": iso.isotropic_length,
                                    "paper_angles": isotropy.to_paper_angles(
                                        positions[0::2]).tolist()}})
        report.append(f"isotropy index {iso.index:.4f} at L = {iso.length:.4f} m"
                      + (" (isotropic)" if iso.isotropic else
                         f" (C1 off by {iso.c1:.3f}, C2 by {iso.c2:.3f})"))
    if args.isotropic_search:
        sets = isotropy.isotropic_configurations(kin)
        result["isotropic_configurations"] = [
            {"kind": s.kind, "angles": list(s.angles), "offsets": list(s.offsets),
             "paper_angles": isotropy.to_paper_angles(s.angles).tolist(), "L": s.length}
            for s in sets]
        report.append(f"isotropic steering configurations ({len(sets)}):")
        for s in sets:
            deg = ", ".join(f"{math.degrees(a):+.1f}" for a in s.offsets)
            if s.kind == "family":
                report.append(f"  family: phi_i - phi_1 = ({deg}) deg, any phi_1 "
                              f"(L = {s.length:.4f} m at phi_1 = 0)")
            else:
                ang = ", ".join(f"{math.degrees(a):+.1f}" for a in s.angles)
                report.append(f"  point: ({ang}) deg, L = {s.length:.4f} m")
        if not sets:
            report.append("  none: no steering configuration of this geometry is isotropic")
    if args.trajectory:
        from holonomic_core.teleop_script import demo_script
        times, samples, starts = holonomicity.rollout(args.robot, demo_script(),
                                                      overrides=overrides)
        index = np.array([isotropy.isotropy(kin, q[0::2]).index for q in samples])
        worst = int(np.argmin(index))
        result["trajectory_isotropy"] = {"min": float(index.min()), "mean": float(index.mean()),
                                         "min_at_s": float(times[worst]),
                                         "samples": len(index)}
        report.append(f"isotropy index along the demo script: min {index.min():.3f} at "
                      f"{times[worst]:.2f} s, mean {index.mean():.3f}")
        if plot_dir is not None:
            figures.append(plots.isotropy_trajectory_plot(
                times, index, starts, f"{model.name}: isotropy along the demo's teleop script",
                plot_dir / f"{model.name}_isotropy_trajectory.png"))
    if args.measure:
        extra = holonomicity.kinematic_overrides(args.robot) if args.kinematic else {}
        m = holonomicity.measure(args.robot, args.distance, args.directions,
                                 args.heading_changes, args.driver, {**overrides, **extra})
        result["measured"] = m.as_dict()
        result["measured"]["kinematic"] = bool(args.kinematic)
        report.append(f"measured holonomicity ({args.driver}"
                      f"{', kinematic limit' if args.kinematic else ''}, d_T {args.distance:g} m, "
                      f"{args.directions} directions): H = {m.H:.3f}")
        for theta in m.thetas:
            times = [mv.seconds for mv in m.moves if mv.theta == theta]
            report.append(f"  heading change {math.degrees(theta):+6.1f} deg: H = "
                          f"{m.h_of(theta):.3f} (t {min(times):.3f} .. {max(times):.3f} s)")
        if plot_dir is not None:
            figures.append(plots.measured_plot(m, model.name,
                                               plot_dir / f"{model.name}_measured_H.png"))
    if figures:
        result["figures"] = [str(f) for f in figures]
        report.append("figures: " + ", ".join(str(f) for f in figures))
    if args.json:
        print(json.dumps(result, indent=1), file=out)
    else:
        print("\n".join(report), file=out)
    return result


def _instantaneous_line(inst: dict) -> str:
    """The report's line on the configuration's own mobility (rolling constraints)."""
    basis = "; ".join("(" + ", ".join(f"{v:+.3f}" for v in b) + ")"
                      for b in inst["mobility_basis"]) or "none: locked"
    t = inst["translation"]
    move = ("no translation" if t is None else
            f"translation only along {math.degrees(t['direction']):+.1f} deg, "
            f"up to {t['speed']:.3f} m/s")
    return (f"  at this configuration: {inst['mobility_dimension']}-D mobility, twists "
            f"(vx, vy, wz) along {basis}; {move}; H_hat {inst['H_hat']:.3f} "
            "(the wheels must turn before any other move)")


def _angle_joints(model) -> list[int]:
    return [i for i, n in enumerate(model.joint_names) if not n.endswith("wheel_joint")]


def main(argv: list[str] | None = None) -> int:
    from holonomic_core.schema import ConfigError
    args = parse_args(argv)
    try:
        run(args)
    except (ConfigError, ValueError, RuntimeError) as exc:
        print(f"holonomic-analyze: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:      # --plot DIR not writable
        print(f"holonomic-analyze: cannot write {exc.filename}: {exc.strerror}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
