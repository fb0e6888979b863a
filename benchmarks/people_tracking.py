"""People tracked over the shared videos (issue 25's tracking bar): YOLOX-Nano boxes linked by
lit_boot.estimate.track_people, per track the frames it covers, and contact sheets with each
track's id and colour drawn on sampled frames (judge identity switches and missed people by eye).
With --poses, also MediaPipe Pose alone (the default estimator) against every tracked person's
pose (estimate_poses(people="all"), top-down, tracked by boxes and keypoints), with their wall
times, and a contact sheet of those people (<video>_people.png).

Usage:
  OMP_NUM_THREADS=1 python benchmarks/people_tracking.py [--videos basketball,football,street]
      [--detector ../shared/checkpoints/yolox_nano.onnx] [--frames 0,10,20] [--out /tmp/people_tracking]
      [--poses] [--smoothing 0.5]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch

from lit_boot.data.readers.video import read_video
from lit_boot.data.visualize import write_png
from lit_boot.estimate import PersonDetector, track_people
from real_data import SHARED

VIDEOS = {"basketball": "data/videos/basketball_1080p_89f.mp4", "football": "data/videos/football_720p_10f",
          "street": "data/videos/street_540p_5f.mp4"}  # fmt: skip
COLOURS = ["red", "lime", "blue", "yellow", "magenta", "cyan", "orange", "white", "purple", "pink", "brown", "gray"]


def sheet(frames: torch.Tensor, tracks: torch.Tensor, picks: list[int]) -> torch.Tensor:
    """The frames ``picks`` side by side (halved) with every track's box and id."""
    from torchvision.utils import draw_bounding_boxes

    out = []
    for t in picks:
        here = [p for p in range(tracks.shape[0]) if tracks[p, t, 4] > 0]
        image = frames[t]
        if here:
            image = draw_bounding_boxes(image, tracks[here, t, :4], labels=[str(p) for p in here], width=3,
                                        colors=[COLOURS[p % len(COLOURS)] for p in here])  # fmt: skip
        out.append(image[:, ::2, ::2])
    return torch.cat(out, dim=2)


def poses(frames: torch.Tensor, detector: PersonDetector) -> tuple[dict, torch.Tensor]:
    """MediaPipe alone against every tracked person's pose: frames with a pose, seconds; and the
    people's boxes (P, T, 5) (the top-down estimator's tracks, linked by boxes and keypoints)."""
    from lit_boot.estimate import estimate_poses

    t0 = time.perf_counter()
    one = estimate_poses(frames, detector=detector)
    t1 = time.perf_counter()
    every = estimate_poses(frames, people="all", detector=detector)
    t2 = time.perf_counter()
    boxes = torch.stack([p.person_boxes for p in every.people()]) if every.person_boxes is not None else None
    return {"default_s": t1 - t0, "default_pose_frames":
            int(one.found().sum()), "people_s": t2 - t1, "people": every.num_people,
            "pose_frames_per_person": [int((p.keypoints_conf > 0).any(-1).sum()) for p in every.people()],
            "not_theirs": [r["not_theirs"] for r in every.metadata["people"]],
            "tracks_without_pose": every.metadata["people_without_pose"]}, boxes  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--videos", default=",".join(VIDEOS))
    parser.add_argument("--detector", type=Path, default=SHARED / "checkpoints/yolox_nano.onnx")
    parser.add_argument("--frames", default=None, help="frames to draw (default: 4 spread over the clip)")
    parser.add_argument("--out", type=Path, default=Path("/tmp/people_tracking"))
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--poses", action="store_true", help="also time the default and the top-down estimator")
    parser.add_argument("--smoothing", type=float, default=None, help="track_people's smoothing (default: its own)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    detector, rows = PersonDetector(args.detector), []
    for name in args.videos.split(","):
        frames = read_video(SHARED / VIDEOS[name]).frames
        start = time.perf_counter()
        detections = detector.detect_frames(frames)
        detect_s = time.perf_counter() - start
        tracks = track_people(detections, **({} if args.smoothing is None else {"smoothing": args.smoothing}))
        track_s = time.perf_counter() - start - detect_s
        T = frames.shape[0]
        picks = [int(v) for v in args.frames.split(",")] if args.frames else sorted({0, T // 3, 2 * T // 3, T - 1})
        write_png(args.out / f"{name}.png", sheet(frames, tracks, picks))
        covered = (tracks[..., 4] > 0).sum(1).tolist()
        rows.append({"video": name, "frames": T, "size": list(frames.shape[2:]),
                     "detections_per_frame": sum(len(d) for d in detections) / T, "tracks": len(tracks),
                     "frames_per_track": covered, "detect_s_per_frame": detect_s / T, "track_s": track_s})  # fmt: skip
        if args.poses:
            found, people = poses(frames, detector)
            rows[-1] |= found
            if people is not None:  # each person with a pose, in its track's colour (ids: people order)
                write_png(args.out / f"{name}_people.png", sheet(frames, people, picks))
        print(json.dumps(rows[-1]))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
