"""Optimiser plumbing for 3DGS fitting: trainable parameter groups, the standard learning rates, the
position learning-rate decay, and Adam-state surgery when Gaussians are added or removed.

The optimiser is Adam (one parameter group per attribute, ``eps = 1e-15`` as in the Inria code), written
out here (:class:`PortableAdam`) with torch's state layout and update formula: ``torch.optim.Adam``'s CPU
kernels (``lerp_``, ``addcmul_``) use fused multiply-adds in their AVX2 / AVX-512 paths and plain multiplies
and adds in the scalar one, so a fit's last bits, which thousands of steps amplify, depended on the CPU it
ran on.  Densification changes the number of rows; :meth:`GaussianParameters.remap` rebuilds every
parameter from a row map and carries each surviving row's Adam moments along (new rows start at zero),
exactly what graphdeco-inria/gaussian-splatting does with ``cat_tensors_to_optimizer`` /
``_prune_optimizer``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import torch

from setdiff_bench.gaussians.model import GaussianModel

PARAM_NAMES = ("means", "sh_dc", "sh_rest", "opacity_logits", "log_scales", "quats")


def exponential_lr(
    step: int,
    lr_init: float,
    lr_final: float,
    max_steps: int,
    *,
    delay_steps: int = 0,
    delay_mult: float = 1.0,
) -> float:
    """Inria's ``get_expon_lr_func``: log-linear interpolation from ``lr_init`` to ``lr_final`` over
    ``max_steps``, optionally warmed up over ``delay_steps`` with a cosine ramp starting at ``delay_mult``."""
    if step < 0 or (lr_init == 0.0 and lr_final == 0.0):
        return 0.0
    if delay_steps > 0:
        delay_rate = delay_mult + (1 - delay_mult) * math.sin(
            0.5 * math.pi * min(max(step / delay_steps, 0.0), 1.0)
        )
    else:
        delay_rate = 1.0
    t = min(max(step / max(max_steps, 1), 0.0), 1.0)
    return delay_rate * math.exp(math.log(lr_init) * (1 - t) + math.log(lr_final) * t)


class PortableAdam(torch.optim.Optimizer):
    """Adam (Kingma & Ba) exactly as ``torch.optim.Adam(foreach=False)`` computes it, with the same bits on
    every CPU: each update is separate element-wise multiplies, adds, a square root and a division, which
    IEEE arithmetic rounds identically at every vector width (no fused multiply-add).

    State per parameter, named as torch names it (so checkpoints and the row surgery below are shared):
    ``step`` (0-d float32 tensor), ``exp_avg`` and ``exp_avg_sq`` (the parameter's shape).
    """

    def __init__(
        self,
        params: list[dict],
        lr: float = 1e-3,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-8,
    ) -> None:
        super().__init__(params, {"lr": lr, "betas": betas, "eps": eps})

    @torch.no_grad()
    def step(self, closure: None = None) -> None:  # type: ignore[override]
        """One Adam update of every parameter that has a gradient."""
        for group in self.param_groups:
            beta1, beta2 = group["betas"]
            for param in group["params"]:
                if param.grad is None:
                    continue
                grad = param.grad
                state = self.state[param]
                if not state:
                    state["step"] = torch.tensor(0.0)
                    state["exp_avg"] = torch.zeros_like(param)
                    state["exp_avg_sq"] = torch.zeros_like(param)
                state["step"] += 1
                step = float(state["step"])
                exp_avg, exp_avg_sq = state["exp_avg"], state["exp_avg_sq"]
                exp_avg.copy_(exp_avg + (grad - exp_avg) * (1.0 - beta1))  # torch's lerp_, unfused
                exp_avg_sq.mul_(beta2).add_(grad * grad * (1.0 - beta2))
                bias_correction1 = 1.0 - beta1**step
                bias_correction2_sqrt = math.sqrt(1.0 - beta2**step)
                denom = (exp_avg_sq.sqrt() / bias_correction2_sqrt).add_(group["eps"])
                param.add_(exp_avg / denom * (-group["lr"] / bias_correction1))


class GaussianParameters:
    """The trainable tensors of a :class:`GaussianModel` with their Adam optimiser.

    Attributes:
        params: name → leaf tensor (``requires_grad``): ``means (N, 3)``, ``sh_dc (N, 1, 3)``,
            ``sh_rest (N, K−1, 3)``, ``opacity_logits (N,)``, ``log_scales (N, 3)``, ``quats (N, 4)``.
        optimizer: :class:`PortableAdam` with one group per name.
    """

    def __init__(self, model: GaussianModel, learning_rates: Mapping[str, float]) -> None:
        m = model.detach()
        tensors = {
            "means": m.means,
            "sh_dc": m.sh[:, :1, :],
            "sh_rest": m.sh[:, 1:, :],
            "opacity_logits": m.opacity_logits,
            "log_scales": m.log_scales,
            "quats": m.quats,
        }
        self.params = {k: v.clone().contiguous().requires_grad_(True) for k, v in tensors.items()}
        self.optimizer = PortableAdam(
            [{"params": [self.params[k]], "lr": float(learning_rates[k]), "name": k} for k in PARAM_NAMES],
            lr=0.0,
            eps=1e-15,
        )

    def __len__(self) -> int:
        return int(self.params["means"].shape[0])

    def model(self) -> GaussianModel:
        """The current Gaussians (differentiable views of the parameters)."""
        p = self.params
        sh = torch.cat([p["sh_dc"], p["sh_rest"]], dim=1) if p["sh_rest"].shape[1] else p["sh_dc"]
        return GaussianModel(p["means"], p["quats"], p["log_scales"], p["opacity_logits"], sh)

    def set_lr(self, name: str, lr: float) -> None:
        for group in self.optimizer.param_groups:
            if group["name"] == name:
                group["lr"] = lr

    def lr(self, name: str) -> float:
        return float(next(g["lr"] for g in self.optimizer.param_groups if g["name"] == name))

    # ------------------------------------------------------------------ row surgery
    def remap(self, source_rows: torch.Tensor, new_values: Mapping[str, torch.Tensor] | None = None) -> None:
        """Rebuild every parameter with ``M`` rows.

        Args:
            source_rows: ``(M,)`` int64; row ``i`` of the new parameters copies old row ``source_rows[i]``
                (value and Adam moments), or is new when ``source_rows[i] < 0`` (moments zero).
            new_values: name → ``(M, ...)`` values replacing the copied values (must cover every new row
                of that parameter); names not given keep the copied values.
        """
        source_rows = source_rows.to(torch.int64)
        has_source = source_rows >= 0
        safe = torch.where(has_source, source_rows, torch.zeros_like(source_rows))
        new_values = dict(new_values or {})
        for group in self.optimizer.param_groups:
            name = group["name"]
            old = group["params"][0]
            with torch.no_grad():
                if name in new_values:
                    value = new_values[name].to(old.dtype).clone()
                else:
                    if bool((~has_source).any()):
                        raise ValueError(f"remap: new rows of {name} need values")
                    value = old.detach()[safe].clone()
            fresh = value.contiguous().requires_grad_(True)
            state = self.optimizer.state.pop(old, None)
            if state:
                shape = (-1,) + (1,) * (old.dim() - 1)
                keep = has_source.view(shape)
                for key in ("exp_avg", "exp_avg_sq"):
                    state[key] = torch.where(
                        keep, state[key][safe], torch.zeros_like(state[key][safe])
                    ).contiguous()
                self.optimizer.state[fresh] = state
            group["params"][0] = fresh
            self.params[name] = fresh

    def set_values(self, name: str, value: torch.Tensor, *, reset_moments: bool = True) -> None:
        """Overwrite a parameter's values in place of its tensor (opacity reset), zeroing its Adam moments."""
        group = next(g for g in self.optimizer.param_groups if g["name"] == name)
        old = group["params"][0]
        fresh = value.detach().to(old.dtype).clone().contiguous().requires_grad_(True)
        state = self.optimizer.state.pop(old, None)
        if state:
            if reset_moments:
                state["exp_avg"] = torch.zeros_like(state["exp_avg"])
                state["exp_avg_sq"] = torch.zeros_like(state["exp_avg_sq"])
            self.optimizer.state[fresh] = state
        group["params"][0] = fresh
        self.params[name] = fresh

    # ------------------------------------------------------------------ checkpoint support
    def state_tensors(self) -> dict[str, torch.Tensor]:
        """Parameters and Adam state as a flat name → tensor dict (for safetensors)."""
        out: dict[str, torch.Tensor] = {}
        for name in PARAM_NAMES:
            p = self.params[name]
            out[f"param/{name}"] = p.detach().contiguous()
            state = self.optimizer.state.get(p)
            if state:
                out[f"adam/exp_avg/{name}"] = state["exp_avg"].contiguous()
                out[f"adam/exp_avg_sq/{name}"] = state["exp_avg_sq"].contiguous()
                out[f"adam/step/{name}"] = torch.as_tensor(state["step"], dtype=torch.float32).reshape(1)
        return out

    def load_state_tensors(self, tensors: Mapping[str, torch.Tensor]) -> None:
        """Restore what :meth:`state_tensors` saved (parameter row counts may differ from the current ones)."""
        for group in self.optimizer.param_groups:
            name = group["name"]
            old = group["params"][0]
            self.optimizer.state.pop(old, None)
            fresh = tensors[f"param/{name}"].clone().contiguous().requires_grad_(True)
            if f"adam/step/{name}" in tensors:
                self.optimizer.state[fresh] = {
                    "step": tensors[f"adam/step/{name}"].reshape(()).clone(),
                    "exp_avg": tensors[f"adam/exp_avg/{name}"].clone(),
                    "exp_avg_sq": tensors[f"adam/exp_avg_sq/{name}"].clone(),
                }
            group["params"][0] = fresh
            self.params[name] = fresh
