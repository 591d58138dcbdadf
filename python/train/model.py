"""The seed's graph recurrent network (thesis section 4.4.2.2-3, ../shared/design/METHOD.md) in
plain PyTorch: message passing through the adjacency built from the edges with `scatter_add`
(no PyTorch Geometric), so that it exports to
ONNX with the graph's nodes and edges as inputs.

One step, for B sequences over one graph of N micro nodes (the map's views). Each map fits its
own PCA, so raw descriptor coordinates mean different things in different maps; the model
therefore sees them only through similarities, which are the same in every basis: node i's
features are its view's cosine to the frame s_i, s_i - max(s) and the z-score of s_i, with the
max, mean and standard deviation of s over the whole map (an input: the nodes may be a window);
the global feature is that [max, mean, std]. On those:
- NodeModel: each node's neighbours are encoded by phi_v (an MLP down to `neighbour_dim`) and
  averaged; phi_vu maps [x_i, mean of neighbours, u] to the node's new feature;
- GlobalModel: phi_u maps [mean over nodes, u] to the new global feature;
- NodeModel again, on the new node features and global feature: X'';
- temporal (optional): Z_k = ReLU(X'' + GCN(Z_{k-1})), one graph convolution with the symmetric
  normalisation of (A + I); without it Z_k = ReLU(X'');
- logits W Z_k + b over the nodes (the softmax is the caller's).
MLPs: Linear, ReLU, dropout, Linear.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn


@dataclass(frozen=True)
class Sizes:
    """Widths of the network; the seed's are hidden 512, neighbour 128, state 512."""

    hidden: int = 512
    neighbour: int = 128
    state: int = 512
    dropout: float = 0.2
    temporal: bool = True


def mlp(inputs: int, hidden: int, outputs: int, dropout: float) -> nn.Sequential:
    return nn.Sequential(
        nn.Linear(inputs, hidden), nn.ReLU(), nn.Dropout(dropout), nn.Linear(hidden, outputs)
    )


def adjacency(edges: Tensor, n: int, dtype: torch.dtype) -> Tensor:
    """The (N, N) matrix A with A[t, s] = number of edges s -> t, from `edges` (2, M).

    Message passing is a dense product with it rather than a scatter of every message: ONNX
    Runtime's ScatterElements with reduction runs element by element (about 70% of a step's
    time over a 40-place window), while one scatter of M ones and a MatMul per pass are
    cheap at window sizes. A flat `scatter_add`, not `index_add` or `index_put`: torch 1.13's
    ONNX export of those scatters without reduction, losing duplicate targets."""
    flat = edges[1] * n + edges[0]
    ones = torch.ones(edges.shape[1], dtype=dtype)
    return torch.zeros(n * n, dtype=dtype).scatter_add(0, flat, ones).reshape(n, n)


def neighbour_mean(values: Tensor, a: Tensor, degree: Tensor) -> Tensor:
    """Mean over each node's in-neighbours of `values` (B, N, F); `a` the adjacency (N, N);
    `degree` (N,) in-degree (at least 1)."""
    return torch.matmul(a, values) / degree[None, :, None]


#: Per-node and global similarity features (see the module's doc).
FEATURES = 3


def similarity_features(nodes: Tensor, frame: Tensor, stats: Tensor) -> tuple[Tensor, Tensor]:
    """Node features (B, N, 3) and global features (B, 3) of the frames (B, D) against the
    nodes (N, D), both unit-norm descriptors; `stats` (B, 3) is [max, mean, std] of the frame's
    similarity over the whole map (the nodes may be a window of it)."""
    s = frame @ nodes.T
    top, mean, std = stats[:, 0:1], stats[:, 1:2], stats[:, 2:3] + 1e-6
    x = torch.stack([s, s - top, (s - mean) / std], dim=2)
    return x, stats


def map_statistics(similarity: Tensor) -> Tensor:
    """(B, 3): [max, mean, std] of each row of `similarity` (B, V) over the map's views."""
    return torch.stack(
        [
            similarity.max(dim=1).values,
            similarity.mean(dim=1),
            similarity.std(dim=1, unbiased=False),
        ],
        dim=1,
    )


class NodeModel(nn.Module):
    def __init__(self, node: int, glob: int, sizes: Sizes, out: int) -> None:
        super().__init__()
        self.phi_v = mlp(node, sizes.hidden, sizes.neighbour, sizes.dropout)
        self.phi_vu = mlp(node + sizes.neighbour + glob, sizes.hidden, out, sizes.dropout)

    def forward(self, x: Tensor, u: Tensor, a: Tensor, degree: Tensor) -> Tensor:
        neighbours = neighbour_mean(self.phi_v(x), a, degree)
        glob = u[:, None, :].expand(-1, x.shape[1], -1)
        return self.phi_vu(torch.cat([x, neighbours, glob], dim=2))


class GlobalModel(nn.Module):
    def __init__(self, node: int, glob: int, sizes: Sizes) -> None:
        super().__init__()
        self.phi_u = mlp(node + glob, sizes.hidden, glob, sizes.dropout)

    def forward(self, x: Tensor, u: Tensor) -> Tensor:
        return self.phi_u(torch.cat([x.mean(dim=1), u], dim=1))


class GRNN(nn.Module):
    """One recurrent step: (node descriptors, edges, frame descriptor, previous state) ->
    (logits over nodes, new state)."""

    def __init__(self, sizes: Sizes) -> None:
        super().__init__()
        self.sizes = sizes
        f = FEATURES
        self.node1 = NodeModel(f, f, sizes, sizes.hidden)
        self.glob = GlobalModel(sizes.hidden, f, sizes)
        self.node2 = NodeModel(sizes.hidden, f, sizes, sizes.state)
        self.gcn = nn.Linear(sizes.state, sizes.state, bias=False)
        self.score = nn.Linear(sizes.state, 1)

    def forward(
        self, nodes: Tensor, edges: Tensor, frame: Tensor, state: Tensor, stats: Tensor
    ) -> tuple[Tensor, Tensor]:
        """`nodes` (N, D) the window's view descriptors; `edges` (2, M) int64 directed, no self
        loops; `frame` (B, D); `state` (B, N, S), zeros at a sequence's start; `stats` (B, 3)
        the frame's similarity statistics over the whole map (`map_statistics`). Returns
        logits (B, N) and the new state (B, N, S)."""
        n = nodes.shape[0]
        a = adjacency(edges, n, nodes.dtype)
        in_degree = a.sum(dim=1)
        x, g = similarity_features(nodes, frame, stats)
        x = self.node1(x, g, a, in_degree.clamp(min=1.0))
        u = self.glob(x, g)
        x = self.node2(x, u, a, in_degree.clamp(min=1.0))
        if self.sizes.temporal:
            # GCN with (A + I) and symmetric normalisation: D^-1/2 (A + I) D^-1/2 Z W.
            norm = (in_degree + 1.0).rsqrt()
            z = self.gcn(state) * norm[None, :, None]
            z = (z + torch.matmul(a, z)) * norm[None, :, None]
            x = x + z
        new_state = torch.relu(x)
        return self.score(new_state).squeeze(2), new_state
