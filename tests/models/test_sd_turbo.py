"""The SD-Turbo architecture builds from config alone (no weights) and runs one 1+1 set on the CPU."""

from __future__ import annotations

import gc

import pytest
import torch

from setdiff_bench.models.setdiff.config_io import load_config
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.model import SetDiffModel
from tests.models.setdiff_fixtures import make_packet

# Published size of the SD 2.x UNet (stabilityai/stable-diffusion-2-1-base, sd-turbo): 865,910,724 parameters.
SD2_UNET_PARAMETERS = 865_910_724
# SD 2.x VAE (AutoencoderKL, 4-channel latent): 83,653,863 parameters.
SD_VAE_PARAMETERS = 83_653_863


@pytest.mark.filterwarnings("ignore::FutureWarning")
def test_sd_turbo_architecture_runs_one_step() -> None:
    config = load_config("sd_turbo_setdiff").model
    torch.manual_seed(0)
    model = SetDiffModel(config).eval()
    try:
        unet_parameters = sum(p.numel() for p in model.unet.parameters())
        assert unet_parameters == SD2_UNET_PARAMETERS
        base_vae = sum(p.numel() for n, p in model.codec.vae.named_parameters() if "lora_" not in n)
        assert base_vae == SD_VAE_PARAMETERS
        # 16 transformer blocks → 16 self-attentions mixed; heads 5/10/20 of dim 64 (the head-dim quirk)
        assert len(model.mixed_attention) == 16
        head_dims = {
            m.to_q.out_features // m.heads for n, m in model.unet.named_modules() if n.endswith("attn1")
        }
        assert head_dims == {64}
        level_heads = {
            n.split(".attentions")[0]: m.heads for n, m in model.unet.named_modules() if n.endswith("attn1")
        }
        assert level_heads["down_blocks.0"] == 5 and level_heads["down_blocks.1"] == 10
        assert level_heads["down_blocks.2"] == 20 and level_heads["mid_block"] == 20
        assert model.text_embedding.shape == (1, 77, 1024)
        output = enhance_packet(model, make_packet(1, 1, size=(64, 64)))
        assert output.shape == (1, 3, 64, 64)
        assert torch.isfinite(output).all()
    finally:
        del model
        gc.collect()
