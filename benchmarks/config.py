# SPDX-License-Identifier: GPL-3.0-or-later
"""Sizes and sweeps of each run mode. `quick` keeps every section but shrinks sizes so the
whole report takes under five minutes on a 2-core machine; `full` uses the issue sizes."""
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Config:
    mode: str
    runs: int = 5                       # timed runs per figure (after one warm-up)
    # 1. generation
    gen_counts: tuple = (1000, 10000, 100000)
    gen_points: int = 32
    gen_keys: int = 10
    # 2. geometry
    geo_presets: tuple = ("straight", "wavy", "curly")
    geo_fixed: tuple = (3, 4, 6, 8, 12, 16, 25, 32, 48, 64)
    geo_tolerances: tuple = (3e-4, 1e-4, 3e-5, 1e-5)
    geo_error_strands: int = 100        # strands whose distance to the exact curve is measured
    geo_render_strands: int = 10000
    geo_render_size: int = 256
    # 3. rendering
    ren_strands: int = 5000
    ren_size: int = 128                 # the float64 reference is numpy: keep images small
    ren_spp: tuple = (1, 4, 9, 16, 25)
    ren_layers: tuple = (1, 2, 4, 8)
    ren_grid_scale: tuple = (0.25, 0.5, 1.0, 2.0)
    ren_aa_ref_spp: int = 64
    # 4. anchors
    anc_counts: tuple = (10000, 100000)
    anc_size: int = 512
    anc_spp: tuple = (1, 16)
    anc_ref_size: int = 128
    anc_real: bool = True
    # 5. scaling
    sca_counts: tuple = (1000, 10000, 50000, 100000, 200000)
    sca_sizes: tuple = (128, 256, 512, 1024)
    sca_lengths: tuple = (0.5, 1.0, 2.0, 4.0)
    sca_fixed_count: int = 20000
    sca_cost_rays: int = 4000
    # 6. skips
    skip_strands: int = 10000
    skip_size: int = 512
    # 7. stress
    stress_examples: int = 200
    # 9. GPU (issue 15 asks for 100,000 and 1,000,000 strands; the thesis for 10,000)
    gpu_counts: tuple = (10000, 100000, 1000000)
    gpu_size: tuple = (1920, 1080)
    # 9. integration (extension, export)
    int_strands: int = 100000
    tfx_vertices: tuple = (4, 8, 16, 32, 64)
    # 14. contact sheet
    contact_cycles_samples: int = 128
    # per-section wall-clock limit in seconds (the section is killed and reported past it)
    limits: dict = field(default_factory=dict)


QUICK = Config(
    mode="quick",
    gen_counts=(1000, 10000, 100000),
    geo_presets=("straight", "wavy", "curly"),
    geo_fixed=(3, 8, 25),
    geo_tolerances=(3e-4,),
    geo_error_strands=40,
    geo_render_strands=1000,
    geo_render_size=64,
    ren_strands=1000,
    ren_size=48,
    ren_spp=(1, 4),
    ren_layers=(1, 2, 4),
    ren_grid_scale=(0.5, 1.0, 2.0),
    ren_aa_ref_spp=64,
    anc_counts=(10000,),
    anc_size=128,
    anc_spp=(1, 16),
    anc_real=True,
    sca_counts=(1000, 3000, 10000),
    sca_sizes=(64, 128, 256),
    sca_lengths=(0.5, 1.0, 2.0),
    sca_fixed_count=5000,
    sca_cost_rays=500,
    skip_strands=3000,
    skip_size=160,
    stress_examples=30,
    int_strands=5000,
    tfx_vertices=(4, 16, 64),
    contact_cycles_samples=128,
    limits={"generation": 150, "geometry": 35, "rendering": 45, "anchors": 90, "scaling": 45,
            "skips": 30, "stress": 25, "gpu": 10, "integration": 40, "export": 40,
            "versions": 300, "preview_defaults": 600, "contact_sheet": 600, "accel": 120,
            "hair_shading": 300, "meshes": 60, "preview_refinement": 240},
)

FULL = Config(
    mode="full",
    # 1,000,000 strands: ~61 M cylinders, split over two buffer textures (anchors, accel).
    anc_counts=(10000, 100000, 1000000),
    limits={"generation": 520, "geometry": 300, "rendering": 240, "anchors": 2200, "scaling": 300,
            "skips": 180, "stress": 100, "gpu": 20, "integration": 320,
            "export": 420, "versions": 600, "preview_defaults": 1800, "contact_sheet": 1500,
            "accel": 1300, "hair_shading": 1200, "meshes": 300, "preview_refinement": 900},
)

GPU = Config(
    mode="gpu",
    limits={"gpu": 600},
)


def for_mode(mode):
    return {"quick": QUICK, "full": FULL, "gpu": GPU}[mode]
