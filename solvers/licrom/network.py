"""LiCROM networks: the PointNet encoder P(X, u) -> q and the neural field W(X), u(X) = W(X) q.

Conventions (shared with `solvers.licrom.train` and the online solver):
- positions X are in metres; the field standardises them itself, Xhat = (X - X_mean) / X_scale, with one
  isotropic scale (so the shape keeps its aspect ratio and a rotation of X is a rotation of Xhat);
- the basis W is dimensionless and the latent coordinates q carry metres: u [m] = W(X) q;
- `r` is always the total number of basis columns. With `affine=True` the first 12 columns are the exact affine
  fields `solvers.reduced.bases.affine_fields(Xhat)` and the network supplies the remaining r - 12 (so r >= 13).
"""

from __future__ import annotations

import torch
from torch import nn

from frictionbench.solvers.reduced.bases import N_AFFINE, affine_fields



class PointNetEncoder(nn.Module):
    """PointNet without feature transform: per-point 64-128-256 layers, max pooling, linear head to r.

    The shared per-point layers are Linear + BatchNorm + ReLU on the flattened points (the same maps as
    Conv1d with kernel 1, faster on the CPU).

    Input points (B, N, 6): standardised rest positions Xhat and scaled displacements, per point. The output
    (B, r) does not depend on the order of the N points.
    """

    def __init__(self, r: int, in_features: int = 6) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        width_in = in_features
        for width in (64, 128, 256):
            layers += [nn.Linear(width_in, width), nn.BatchNorm1d(width), nn.ReLU()]
            width_in = width
        self.features = nn.Sequential(*layers)
        self.head = nn.Linear(width_in, r)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """points (B, N, 6) -> latent codes (B, r)."""
        B, N, _ = points.shape
        per_point = self.features(points.reshape(B * N, -1)).view(B, N, -1)  # (B, N, 256); BN over all B N points
        return self.head(per_point.amax(dim=1))


def affine_features(Xhat: torch.Tensor) -> torch.Tensor:
    """Xhat (n, 3) standardised rest positions -> phi (n, 4) = [1, Xhat_x, Xhat_y, Xhat_z]."""
    return torch.cat([torch.ones_like(Xhat[:, :1]), Xhat], dim=1)


def fit_affine(Xhat: torch.Tensor, u: torch.Tensor, weights: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Weighted least-squares affine part of displacement frames.

    Xhat: (n, 3) standardised rest positions; u: (F, n, 3) displacements [m]; weights: (n,) point weights
    (e.g. lumped masses), positive somewhere on at least 4 non-coplanar points.
    Returns q_affine (F, 12) [m], coefficients of `affine_fields`, and the residual u - A q_affine (F, n, 3),
    which is orthogonal to every affine field in the weighted inner product sum_i w_i a_i . v_i.
    """
    phi = affine_features(Xhat)  # (n, 4)
    gram = phi.T @ (weights[:, None] * phi)  # (4, 4)
    coef = torch.linalg.solve(gram, torch.einsum("n,nk,fnc->fkc", weights, phi, u))  # (F, 4, 3)
    residual = u - torch.einsum("nk,fkc->fnc", phi, coef)
    return coef.transpose(1, 2).reshape(u.shape[0], N_AFFINE), residual


class NeuralField(nn.Module):
    """The basis W: R^3 -> R^{3 x r}, an ELU MLP of the rest position (C^1 in X).

    r: total basis columns; width, depth: hidden layer width and number of hidden layers (LiCROM: 60 x 5).
    affine: prepend the 12 exact affine columns; the network's r - 12 columns are then projected onto the
        weighted orthogonal complement of the affine span over the reference points, W_nn = N - A C with
        C = (Phi^T D Phi)^-1 Phi^T D N(ref) per component (D = diag(ref_w)). The split is thus unique: affine
        motion is carried by the affine columns alone and the reduced mass W^T M W stays well conditioned.
    X_mean (3,) [m], X_scale [m]: standardisation of X; ref_X (n_ref, 3) [m], ref_w (n_ref,): reference points
        and weights of the orthogonalisation (required iff affine). All are buffers, saved in the state dict.
    """

    def __init__(
        self,
        r: int,
        width: int = 60,
        depth: int = 5,
        affine: bool = False,
        X_mean: torch.Tensor | None = None,
        X_scale: float = 1.0,
        ref_X: torch.Tensor | None = None,
        ref_w: torch.Tensor | None = None,
    ) -> None:
        super().__init__()
        n_neural = r - N_AFFINE if affine else r
        if n_neural < 1:
            raise ValueError(f"r = {r}: need r >= {N_AFFINE + 1 if affine else 1} (affine = {affine})")
        if affine and (ref_X is None or ref_w is None):
            raise ValueError("affine = True needs reference points ref_X and weights ref_w")
        self.r, self.width, self.depth, self.affine, self.n_neural = r, width, depth, affine, n_neural
        layers: list[nn.Module] = []
        width_in = 3
        for _ in range(depth):
            layers += [nn.Linear(width_in, width), nn.ELU()]
            width_in = width
        layers.append(nn.Linear(width_in, 3 * n_neural))
        self.mlp = nn.Sequential(*layers)
        for layer in self.mlp:
            if isinstance(layer, nn.Linear):
                nn.init.xavier_uniform_(layer.weight)
                nn.init.zeros_(layer.bias)
        self.register_buffer("X_mean", torch.zeros(3) if X_mean is None else X_mean.detach().clone().float())
        self.register_buffer("X_scale", torch.tensor(float(X_scale)))
        if affine:
            self.register_buffer("ref_X", ref_X.detach().clone().float())
            self.register_buffer("ref_w", ref_w.detach().clone().float())

    def standardise(self, X: torch.Tensor) -> torch.Tensor:
        """X (..., 3) [m] -> Xhat (..., 3) [-]."""
        return (X - self.X_mean) / self.X_scale

    def _network(self, Xhat: torch.Tensor) -> torch.Tensor:
        """Raw network columns (n, 3, n_neural) at standardised positions Xhat (n, 3)."""
        return self.mlp(Xhat).view(Xhat.shape[0], 3, self.n_neural)

    def forward(self, X: torch.Tensor) -> torch.Tensor:
        """X (n, 3) rest positions [m] -> W (n, 3, r) [-]; affine columns first when `affine`."""
        Xhat = self.standardise(X)
        columns = self._network(Xhat)
        if not self.affine:
            return columns
        columns = columns - torch.einsum("nk,ckj->ncj", affine_features(Xhat), self._affine_coefficients())
        return torch.cat([affine_fields(Xhat), columns], dim=2)

    def _affine_coefficients(self) -> torch.Tensor:
        """C (3, 4, n_neural): weighted least-squares affine part of the network columns on the reference points."""
        ref_hat = self.standardise(self.ref_X)
        phi = affine_features(ref_hat)
        gram = phi.T @ (self.ref_w[:, None] * phi)
        moments = torch.einsum("m,mk,mcj->ckj", self.ref_w, phi, self._network(ref_hat))
        return torch.linalg.solve(gram, moments)
