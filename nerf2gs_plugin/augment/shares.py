"""How the training samples are shared between the input views and each view family's views.

Each family has its own share: the probability that a training sample is one of its views
(``--augment.birds-eye-share``, ``--augment.lane-shift.share``, ...), drawn uniformly among that
family's views. A share left at None is the family's views' share of them and the input views (the
draw of one image among all, as when the bird's-eye views were the only family), at most
:data:`DEFAULT_SHARE_CAP`, taken out of what the input views have left once the families before it (in
the order of ``--augment.views``) are served: so a family added after the others takes samples from the
input views only.
``--augment.extra-prob``, when set, is the probability of all additional views together, split
between the families in proportion to their shares.
"""

from __future__ import annotations

from typing import Any, Optional

import torch
from torch import Tensor

from nerf2gs_plugin.engine.augment_config import check_given_shares, given_share, share_flag
from nerf2gs_plugin.errors import ConfigError


DEFAULT_SHARE_CAP = 0.35
"""The most a family's share left at None takes: with as many views from above as input views the draw among
all gives them half the samples, and the input views' street level pays for it; at 0.35 the synthetic streets'
validation views keep their gain from above within 0.1 dB and gain at street level, and the real captures'
validation frames gain on three of four (docs/augmentation.md, "Street level")."""


def family_shares(families: list[str], n_real: int, augment: Any) -> dict[str, float]:
    """Family -> the probability that a training sample is one of its views, for the additional
    views whose families are ``families`` (one name per view) beside ``n_real`` input views."""
    check_given_shares(augment)
    counts = {f: families.count(f) for f in dict.fromkeys(families)}
    order = [f for f in augment.views if f in counts] + [f for f in counts if f not in augment.views]
    shares: dict[str, float] = {}
    left = 1.0  # the input views' share so far: each family in turn takes its share out of it
    for f in order:
        given = given_share(augment, f)
        shares[f] = float(given) if given is not None else min(DEFAULT_SHARE_CAP, left * counts[f] / (n_real + counts[f]))
        left -= shares[f]
    if left <= 0 and augment.extra_prob is None:
        raise ConfigError(f"the view families' shares add up to {1 - left:g}: the input views need some samples "
                          f"({', '.join(f'{f} {s:.3g}' for f, s in shares.items())})", " ".join(share_flag(f) for f in order))
    if augment.extra_prob is not None:
        total = sum(shares.values())
        shares = {f: (augment.extra_prob * s / total if total > 0 else augment.extra_prob * counts[f] / len(families))
                  for f, s in shares.items()}
    return shares


def extra_sampling(families: list[str], n_real: int, augment: Any) -> tuple[float, Optional[Tensor]]:
    """The probability that a sample is an additional view, and each additional view's probability
    among them (None: all alike, a single family: the uniform draw of a run before the families)."""
    shares = family_shares(families, n_real, augment)
    total = sum(shares.values())
    if len(shares) <= 1 or total <= 0:
        return total, None
    counts = {f: families.count(f) for f in shares}
    per_view = torch.tensor([shares[f] / counts[f] for f in families], dtype=torch.float64)
    return total, per_view / per_view.sum()
