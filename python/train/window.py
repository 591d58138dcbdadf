"""The candidate window the GRNN runs on, so that its time per frame does not grow with the map
(one step over a whole 300-place map's 3,600 views takes 15-45 ms in PyTorch on one core even at
widths 32-128; over 20 places' 240 views, 1-2 ms). The Rust estimator must choose the same
window.

Per frame, the window's places are: the `APPEARANCE` places whose best view is most similar to
the frame; the `CARRIED` most probable places of the previous frame's posterior; and the graph
neighbours of the previous most probable place. Its micro nodes are those places' views (in
ascending view order), its edges the micro edges between them. A view that was in the previous
window keeps its state; a new one starts from zeros.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from numpy.typing import NDArray
from torch import Tensor

APPEARANCE = 24
CARRIED = 8


@dataclass
class Window:
    """One frame's window over a world's views."""

    views: NDArray[np.int64]  # (n,) the map views in the window, ascending
    edges: Tensor  # (2, m) int64, window-local indices
    places: NDArray[np.int64]  # (n,) each window view's place


class Windows:
    """Window selection over one world: its views' places, neighbours and micro edges."""

    def __init__(
        self,
        view_place: NDArray[np.int64],
        micro_edges: NDArray[np.int64],
        place_edges: NDArray[np.int64],
    ) -> None:
        self.view_place = view_place
        self.places = int(view_place.max()) + 1
        self.edges = micro_edges
        self.neighbours: list[list[int]] = [[] for _ in range(self.places)]
        for p, q in place_edges:
            self.neighbours[int(p)].append(int(q))
            self.neighbours[int(q)].append(int(p))

    def place_similarity(self, similarity: NDArray[np.float32]) -> NDArray[np.float32]:
        """(P,): each place's best view's similarity to the frame."""
        best = np.full(self.places, -np.inf, dtype=np.float32)
        np.maximum.at(best, self.view_place, similarity)
        return best

    def choose(self, similarity: NDArray[np.float32], previous: dict[int, float] | None) -> Window:
        """The window for a frame whose view similarities are `similarity` (V,), after a frame
        whose place posterior was `previous` (place -> probability; None at the start)."""
        by_place = self.place_similarity(similarity)
        chosen = set(np.argsort(-by_place, kind="stable")[:APPEARANCE].tolist())
        if previous:
            ranked = sorted(previous, key=lambda p: -previous[p])
            chosen.update(ranked[:CARRIED])
            chosen.update(self.neighbours[ranked[0]])
        mask = np.isin(self.view_place, np.fromiter(chosen, dtype=np.int64))
        views = np.flatnonzero(mask)
        local = np.full(len(self.view_place), -1, dtype=np.int64)
        local[views] = np.arange(len(views))
        keep = mask[self.edges[0]] & mask[self.edges[1]]
        edges = torch.from_numpy(local[self.edges[:, keep]])
        return Window(views, edges, self.view_place[views])


def carry_state(state: Tensor, before: NDArray[np.int64], after: NDArray[np.int64]) -> Tensor:
    """The state (1, len(after), S) of the new window: rows of views in both windows copied from
    `state` (1, len(before), S), zeros elsewhere."""
    out = torch.zeros(state.shape[0], len(after), state.shape[2], dtype=state.dtype)
    common, in_after, in_before = np.intersect1d(after, before, return_indices=True)
    if len(common):
        out[:, torch.from_numpy(in_after)] = state[:, torch.from_numpy(in_before)]
    return out


def place_posterior(window: Window, logits: Tensor) -> dict[int, float]:
    """The window's place posterior (place -> probability) from the step's logits (1, n)."""
    views = torch.softmax(logits[0], dim=0).detach().numpy()
    out: dict[int, float] = {}
    for place, p in zip(window.places.tolist(), views.tolist()):
        out[place] = out.get(place, 0.0) + p
    return out
