"""Every person of a scene on one person axis: what a refiner optimises at once.

A refiner's variables carry a person axis after the frames, (T, P, J, D); its loss terms see
the people side by side on the joint axis, (T, P*J, D). Every term is a sum over joints (and
bones) averaged over frames, so the loss is the sum of the people's own losses, and Adam is
element-wise: refining P people at once follows the same path as P single-person runs (up to
the early stop, which watches the total loss), in one run with P times the points. P = 1 is
the single-person refiner, term for term.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torchmetrics import Metric

from ..core import Person, Scene
from ..metrics import people_metric_objects

__all__ = ["PEOPLE_CHOICES", "refined_people", "side_by_side", "TruthIndex", "people_metrics", "unrefined_people"]

#: all: every person of the scene is refined; main: the main person only (the others keep
#: their estimates).
PEOPLE_CHOICES = ("all", "main")


def refined_people(scene: Scene, people: str) -> list[Person]:
    """The people a refiner optimises (``people``: one of :data:`PEOPLE_CHOICES`), main first."""
    if people not in PEOPLE_CHOICES:
        raise ValueError(f"people: expected one of {PEOPLE_CHOICES}, got {people!r}")
    return scene.people() if people == "all" else [Person.of(scene)]


def side_by_side(values: torch.Tensor) -> torch.Tensor:
    """(N, P, J, ...) -> (N, P*J, ...): the people side by side on the joint axis (a view)."""
    return values.reshape(values.shape[0], values.shape[1] * values.shape[2], *values.shape[3:])


class TruthIndex:
    """The refined people's ground truth: for each field, the people who have it (their indices
    on the person axis) and their values stacked (T, G, ...)."""

    def __init__(self, scene: Scene, people: Sequence[Person], fields: Sequence[str]):
        truths = scene.gt.truths([p.track_id for p in people]) if scene.gt is not None else [None] * len(people)
        self.values: dict[str, torch.Tensor | None] = {}
        self.people: dict[str, list[int]] = {}
        for name in fields:
            have = [p for p, truth in enumerate(truths) if truth is not None and getattr(truth, name) is not None]
            self.people[name] = have
            self.values[name] = torch.stack([getattr(truths[p], name).float() for p in have], 1) if have else None


def people_metrics(
    track_ids: Sequence[int], scored: dict[int, dict[str, Metric]]
) -> dict[str, float]:
    """The values of each person's metric objects (``scored``: {person index: {name: metric}})
    under lit-boot's names: the main person's bare, pooled ``_all`` and ``_person<id>`` with
    several people (:func:`~lit_boot.metrics.suite.people_metric_objects`)."""
    per_person = [scored.get(p, {}) for p in range(len(track_ids))]
    metrics = people_metric_objects(per_person, list(track_ids))
    return {name: float(metric.compute()) for name, metric in metrics.items()}


def unrefined_people(scene: Scene, refined: Sequence[Person], fields: Sequence[str]) -> list[Person]:
    """The scene's people that are not among ``refined``, carrying only ``fields`` (the fields a
    refiner's result has), as they were: a result lists every person of its scene."""
    done = {p.track_id for p in refined}
    return [Person(p.track_id, **{k: getattr(p, k) for k in fields}) for p in scene.people() if p.track_id not in done]
