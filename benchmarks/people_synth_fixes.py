"""The ids fixed by hand, end to end, on synthetic scenes with several people: how many fixes a
user writes (``lit-boot ids --fix``) to leave no identity switch of the poses, and whether each lies
in the frames the product lists to check.

Each scene goes through ``estimate_poses(frames, people="all", detector=YOLOX-Nano)`` as in
``people_synth_e2e.py`` (the same scenes, seeds, scoring of the poses: :func:`pose_owners`). Then a
user who knows the truth (a scratch oracle, standing in for one who looked at the frames): each
true person's own track is the returned person whose poses lie on it most often (an optimal
assignment of true people to returned ones by those counts; a true person left without one gets a
new person, ``split``); in every frame, a pose on a true person held by another track goes to
that person's own track by a ``swap`` of the two tracks there; a swap repeated over consecutive
frames is one fix (``swap A B at F-G``). The fixes are applied with :func:`lit_boot.estimate.fix_ids`
and the poses scored again. Per scene: the poses' switches before and after, the fixes, and the
fixes whose first frame is not among the frames to check of the person or people they name (where
a user looking at the listed frames would not have seen what the fix mends).

Usage: OMP_NUM_THREADS=1 python benchmarks/people_synth_fixes.py [--people 2,3] [--seeds 30,31,32,33]
           [--frames 16] [--height 256] [--width 512] [--show]
"""

from __future__ import annotations

import torch
from scipy.optimize import linear_sum_assignment

from lit_boot.estimate import PersonDetector, estimate_poses, fix_ids, frames_to_check
from lit_boot.synth import make_scene
from people_synth_e2e import package_versions, pose_owners, pose_switches, visible_boxes
from people_synth_tracking import MOTIONS, scene_parser, true_people
from real_data import SHARED


def own_tracks(owners: list[list[int | None]], Q: int) -> list[int | None]:
    """Per true person, the returned person (index < Q) whose poses lie on it most often, an optimal
    assignment of the counts (None: a true person with no pose, or none left for it)."""
    counts = torch.zeros(len(owners), max(Q, 1))
    for p, row in enumerate(owners):
        for q in row:
            if q is not None:
                counts[p, q] += 1
    rows, cols = linear_sum_assignment(-counts.numpy())
    out: list[int | None] = [None] * len(owners)
    for p, q in zip(rows, cols):
        out[p] = int(q) if counts[p, q] > 0 else None
    return out


def oracle_fixes(owners: list[list[int | None]], ids: list[int]) -> list[tuple[str, str, int, int]]:
    """The fixes (module docstring) in the order to apply them, as (verb, "A B" or "A", first frame,
    last frame), from ``owners`` (:func:`pose_owners`) and the returned people's track ``ids``."""
    ids = list(ids)
    own = own_tracks(owners, len(ids))
    fixes: list[tuple[str, str, int, int]] = []
    previous: list[tuple[str, str]] = []
    for t in range(len(owners[0]) if owners else 0):
        content = {k: k for k in range(len(ids))}  # track k's row at t holds the pose first on track content[k]
        steps = []
        for p, row in enumerate(owners):
            if row[t] is None:
                continue
            now = next(k for k, v in content.items() if v == row[t])
            if own[p] is None:  # a true person without a track of its own: split its pose off here
                ids.append(max(ids) + 1)
                own[p] = len(ids) - 1
                content[own[p]], content[now] = content[now], None
                steps.append(("split", str(ids[now])))
            elif now != own[p]:
                steps.append(("swap", f"{ids[now]} {ids[own[p]]}"))
                content[now], content[own[p]] = content[own[p]], content[now]
        if t > 0 and steps and steps == previous and all(verb == "swap" for verb, _ in steps):
            fixes[-len(steps):] = [(verb, who, a, t) for verb, who, a, _ in fixes[-len(steps):]]
        else:
            fixes += [(verb, who, t, t) for verb, who in steps]
        previous = steps
    return fixes


def sentence(fix: tuple[str, str, int, int]) -> str:
    verb, who, a, b = fix
    frames = str(a) if a == b else f"{a}-{b}"
    return f"{verb} {who} at {frames}"


def main() -> None:
    parser = scene_parser(__doc__.splitlines()[0])
    parser.add_argument("--height", type=int, default=256)
    parser.add_argument("--width", type=int, default=512)
    parser.add_argument("--show", action="store_true", help="print each scene's fixes")
    args = parser.parse_args()
    detector = PersonDetector(str(SHARED / "checkpoints" / "yolox_nano.onnx"))
    print(f"packages: {package_versions()}")
    print("| scene | poses' switches before | fixes (first frame not listed to check) | switches after |")
    print("| --- | --- | --- | --- |")
    totals = [0, 0, 0, 0, 0]  # switches before, fixes, not listed, after, frames with a pose before - after
    for n in (int(v) for v in args.people.split(",")):
        for i, seed in enumerate(int(v) for v in args.seeds.split(",")):
            scene = make_scene(frames=args.frames, height=args.height, width=args.width, seed=seed, people=n,
                               motion=MOTIONS[i % len(MOTIONS)])  # fmt: skip
            every = estimate_poses(scene.frames, people="all", detector=detector)
            people = [p for p in every.people() if p.keypoints_conf.amax() > 0]
            truths, visible = true_people(scene), visible_boxes(scene, 50)[..., 4] > 0
            owners = pose_owners(people, truths, visible, 0.15)
            before = pose_switches(owners)
            fixes = oracle_fixes(owners, [p.track_id for p in people]) if people else []
            marks = {p.track_id: m for p, m in zip(people, frames_to_check(people))}
            listed = lambda who, t: any(int(x) in marks and bool(marks[int(x)][t]) for x in who.split())  # noqa: E731
            outside = sum(1 for _, who, a, _ in fixes if not listed(who, a))
            fixed = fix_ids(people, [sentence(f) for f in fixes])[0] if fixes else people
            after = pose_switches(pose_owners(fixed, truths, visible, 0.15))
            row = [sum(r["pose_switches"] for r in before), len(fixes), outside, sum(r["pose_switches"] for r in after),
                   sum(r["pose_frames"] for r in before) - sum(r["pose_frames"] for r in after)]  # fmt: skip
            totals = [a + b for a, b in zip(totals, row)]
            shown = f" ({'; '.join(sentence(f) for f in fixes)})" if args.show and fixes else ""
            print(f"| {n} people, s{seed} | {row[0]} | {row[1]} ({row[2]}){shown} | {row[3]} |", flush=True)
    print(f"poses' switches {totals[0]}; fixes {totals[1]} ({totals[2]} whose first frame is not listed to check); "
          f"switches after the fixes {totals[3]}; frames with a pose on a true person lost {totals[4]}")


if __name__ == "__main__":
    main()
