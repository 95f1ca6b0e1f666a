"""Binary classification metrics for patch / point contact predictions (pure torch)."""

from __future__ import annotations

import torch


def binary_metrics(logits: torch.Tensor, labels: torch.Tensor) -> dict[str, float]:
    """Accuracy, precision, recall, F1 at threshold 0.5, and AUROC (rank statistic, ties averaged)."""
    logits, labels = logits.flatten().float(), labels.flatten().bool()
    pred = logits > 0
    tp = (pred & labels).sum().item()
    fp = (pred & ~labels).sum().item()
    fn = (~pred & labels).sum().item()
    precision = tp / (tp + fp) if tp + fp else 0.0
    recall = tp / (tp + fn) if tp + fn else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    n_pos, n_neg = labels.sum().item(), (~labels).sum().item()
    auroc = float("nan")
    if n_pos and n_neg:
        order = logits.argsort()
        ranks = torch.empty_like(logits)
        ranks[order] = torch.arange(1, len(logits) + 1, dtype=logits.dtype)
        # Average the ranks of tied scores.
        values, inverse, counts = torch.unique(logits, return_inverse=True, return_counts=True)
        sums = torch.zeros_like(values).index_add_(0, inverse, ranks)
        ranks = (sums / counts)[inverse]
        auroc = ((ranks[labels].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg)).item()
    return {"accuracy": (pred == labels).float().mean().item(), "precision": precision,
            "recall": recall, "f1": f1, "auroc": auroc, "positive_fraction": n_pos / len(labels)}
