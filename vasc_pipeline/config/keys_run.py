"""The key table's entries of the model and its search: ``physics.*``, ``anneal.*``, ``terminals.*``
and ``method.*`` (:mod:`vasc_pipeline.config.keys`)."""

from __future__ import annotations

from dataclasses import replace

from .keyspec import (
    BOOLEAN,
    NON_NEGATIVE,
    POSITIVE,
    PROBABILITY,
    SHARE,
    Key,
    OneOf,
    Range,
    packing_on,
    supply_schedule_on,
    viscosity_laws,
)
from .rules import MAX_STEPS, SWEPT_KEYS
from .schema import (
    ANNEAL_INITS,
    GAMMA_RANGE,
    MAX_CALIBRATION_SAMPLES,
    MAX_COARSE_EXCLUSION_FACTOR,
    METHODS,
)

__all__ = ["RUN_KEYS"]

RUN_KEYS: tuple[Key, ...] = (
    Key(
        "physics.gamma",
        "1",
        (
            "bifurcation exponent γ: r = r_t n^(1/γ) (measured trees: 2–3; far outside, the radii span "
            "hundreds of decades and the flow solve is singular)"
        ),
        default="7/3 (`model=physiological`); {} (`model=paper`); `plane2d`: 3.0",
        accepted="{}",
        check=Range(
            *GAMMA_RANGE,
            why=" (the bifurcation exponent of r_parent^gamma = sum r_child^gamma: Murray's 3, the paper's 2.1)",
        ),
    ),
    Key(
        "physics.inlet_radius",
        "m",
        "combined inlet radius r_in: Σ_k r_k^γ = r_in^γ",
        default="{} (`plane2d`: 2.4e-3)",
        accepted="{}",
        check=POSITIVE,
    ),
    Key("physics.total_flow", "m³ s⁻¹", "total inflow Q0", accepted="{}", check=POSITIVE),
    Key(
        "physics.m_b", "W m⁻³", "metabolic cost of blood volume (a sweep axis)", accepted="{}", check=SWEPT_KEYS["m_b"]
    ),
    Key("physics.viscosity", "Pa s", "blood viscosity μ in large vessels", accepted="{}", check=POSITIVE),
    Key(
        "physics.viscosity_law",
        "–",
        (
            "how the viscosity varies with the diameter D: `constant`, or μ(D) / μ(large) from Pries' fit "
            "at hematocrit 0.45 in glass tubes (`pries_in_vitro`) or in living microvessels (`pries_in_vivo`) "
            "([The costs](model.md#the-costs))"
        ),
        default="`pries_in_vivo` (`model=physiological`); {} (`model=paper`)",
        accepted="{}",
        check=OneOf(viscosity_laws),
    ),
    Key(
        "physics.r_cutoff",
        "m",
        "only segments with r > r_cutoff pay the exclusion term",
        default="2e-4 (`model=physiological`); {} (`model=paper`, the paper's 0.01 mm)",
        accepted="{}",
        check=NON_NEGATIVE,
    ),
    Key(
        "physics.r_cutoff_ramp",
        "m",
        (
            "the exclusion term's weight rises linearly from 0 at r_cutoff to 1 at r_cutoff + r_cutoff_ramp; "
            "0: a step at r_cutoff ([The costs](model.md#the-costs))"
        ),
        default="2e-4 (`model=physiological`); {} (`model=paper`)",
        accepted="{}",
        check=NON_NEGATIVE,
    ),
    Key("physics.A_wv", "1", "weight of C_w + C_v; the total is divided by it", accepted="{}", check=POSITIVE),
    Key(
        "physics.A_o",
        "1",
        "weight of the exclusion term",
        default="{} (`plane2d`: 0)",
        accepted="{}",
        check=NON_NEGATIVE,
    ),
    Key(
        "physics.A_p",
        "1",
        "weight of the pressure term",
        default="1e-9 (`model=physiological`); {} (`model=paper`: off)",
        accepted="{}",
        check=NON_NEGATIVE,
    ),
    Key("physics.A_s", "1", "weight of the supply term", accepted="{}", check=NON_NEGATIVE),
    Key(
        "physics.pressure_inlet",
        "Pa",
        "inlet pressure, for C_p",
        default="{} (100 mmHg)",
        accepted="> `pressure_terminal`",
    ),
    Key(
        "physics.pressure_terminal",
        "Pa",
        "target terminal pressure P_term, for C_p",
        default="{}",
        accepted="{}",
        check=NON_NEGATIVE,
    ),
    Key("anneal.name", "–", "the preset's name", accepted="any label"),
    Key(
        "anneal.T_start",
        "W",
        (
            "start temperature; null: calibrated so that uphill moves of a random walk from the initial "
            "tree are accepted with mean probability `accept_start`"
        ),
        accepted="{}; > the end temperature",
        check=Range(0, lo_open=True, null=True),
    ),
    Key(
        "anneal.T_start_min",
        "W",
        (
            "a calibrated start temperature is raised to this; null: not raised. The calibration "
            "reads the typical move, whose cost falls with N, while the trunks' barriers do not"
        ),
        default="heart: 100 (`model=physiological`); else {}",
        accepted="{}",
        check=Range(0, lo_open=True, null=True),
    ),
    Key(
        "anneal.T_end",
        "W",
        ("end temperature; null: `T_end_rel` times the cost of one terminal segment of length R_supply"),
        accepted="{}; < `T_start`",
        check=Range(0, lo_open=True, null=True),
    ),
    Key("anneal.accept_start", "1", "mean uphill acceptance at a calibrated T_start", accepted="{}", check=SHARE),
    Key(
        "anneal.T_end_rel",
        "1",
        "calibrated T_end relative to one terminal segment's cost",
        accepted="{}",
        check=POSITIVE,
    ),
    Key(
        "anneal.calibration_samples",
        "moves",
        "infinite-temperature moves measured for T_start (on a copy: the run's stream is untouched)",
        accepted="{}",
        check=Range(1, MAX_CALIBRATION_SAMPLES, integer=True),
    ),
    Key(
        "anneal.steps",
        "moves",
        "proposed moves of the run, exact; null: `steps_at_1000` (N/1000)^`steps_exponent`",
        accepted="{}, or null",
        check=replace(SWEPT_KEYS["steps"], null=True),
    ),
    Key(
        "anneal.steps_at_1000",
        "moves",
        "the budget at N = 1000",
        accepted=f"{{}}; the scheduled total ≤ {MAX_STEPS:.0e}".replace("e+", "e"),
        check=POSITIVE,
    ),
    Key("anneal.steps_exponent", "1", "the budget law's exponent in N", accepted="{}", check=Range(0, 4)),
    Key(
        "anneal.packing_steps_per_terminal",
        "moves",
        "packing phase: the first k·N proposals move terminals only, on ΔC_s alone; 0: off",
        accepted="{}; its moves < the run's; not with `terminals.fixed`",
        check=NON_NEGATIVE,
    ),
    Key(
        "anneal.packing_T_start",
        "voxels of one supply sphere",
        "the packing phase's start temperature",
        accepted="{} (with packing)",
        check=POSITIVE,
        applies=packing_on,
    ),
    Key(
        "anneal.packing_T_end",
        "C_s units",
        "its end temperature",
        accepted="{} (with packing)",
        check=POSITIVE,
        applies=packing_on,
    ),
    Key("anneal.p_swap", "1", "share of the proposals that are swaps", accepted="{}", check=PROBABILITY),
    Key(
        "anneal.p_local",
        "1",
        "share of the swaps whose partner comes from the neighbouring cells",
        accepted="{}",
        check=PROBABILITY,
    ),
    Key(
        "anneal.neighbour_cell",
        "R_supply",
        "edge of those cells (partners from the cell and the 26 around it; 2-D: 8)",
        accepted="{}",
        check=POSITIVE,
    ),
    Key(
        "anneal.step_terminal",
        "R_supply",
        "terminal translation half-width (the cap when adapted)",
        accepted="{}",
        check=POSITIVE,
    ),
    Key(
        "anneal.step_bifurcation",
        "R_supply",
        "bifurcation translation half-width (the cap when adapted)",
        accepted="{}",
        check=POSITIVE,
    ),
    Key(
        "anneal.supply_T_start",
        "voxels of one supply sphere",
        ("supply's own temperature at the start; null: supply searched downhill throughout (the paper)"),
        accepted="{}",
        check=Range(0, lo_open=True, null=True),
    ),
    Key(
        "anneal.supply_T_end",
        "C_s units",
        "its temperature at the end of its phase (0.05: +1 accepted at e^-20)",
        accepted="{} and < `supply_T_start` (with a supply schedule)",
        check=POSITIVE,
        applies=supply_schedule_on,
    ),
    Key(
        "anneal.supply_phase",
        "share of the moves",
        "how long the supply schedule runs; then the true weight A_s/A_wv",
        accepted="{}",
        check=Range(0, 1, lo_open=True),
    ),
    Key("anneal.adapt_steps", "–", "adapt the translation half-widths to `acceptance_target`", accepted="true, false"),
    Key(
        "anneal.acceptance_target",
        "1",
        "the adapted steps' target acceptance, per node class",
        accepted="{}",
        check=SHARE,
    ),
    Key(
        "anneal.adapt_window",
        "proposals",
        "proposals of a class between adaptations",
        accepted="{}",
        check=Range(1, MAX_CALIBRATION_SAMPLES, integer=True),
    ),
    Key(
        "anneal.full_width_phase",
        "share of the moves",
        "with adapted steps: how long half of the terminal moves keep the full width",
        accepted="{}",
        check=Range(0, 1, lo_open=True),
    ),
    Key(
        "anneal.cold_from",
        "share of the path",
        "where the schedule's cold part starts; null: one exponential",
        accepted="{}; set with `cold_share`",
        check=replace(SHARE, null=True),
    ),
    Key(
        "anneal.cold_share",
        "share of the tree anneal's moves",
        "the moves spent in the cold part",
        accepted="{}; set with `cold_from`",
        check=replace(SHARE, null=True),
    ),
    Key(
        "anneal.coarse_exclusion_factor",
        "voxels per coarse voxel edge",
        ("the exclusion term on a depth map this many times coarser early in the run; null: the true map throughout"),
        accepted="{}; set with `coarse_exclusion_phase`",
        check=Range(2, MAX_COARSE_EXCLUSION_FACTOR, integer=True, null=True, why=" (voxels per coarse voxel edge)"),
    ),
    Key(
        "anneal.coarse_exclusion_phase",
        "share of the tree anneal's moves",
        "how long the coarse map serves",
        accepted="{}; set with the factor",
        check=replace(SHARE, null=True),
    ),
    Key(
        "anneal.polish",
        "–",
        "bifurcations moved to the final topology's optimum where the total cost does not rise",
        accepted="true, false",
    ),
    Key(
        "anneal.polish_swaps_max_terminals",
        "terminals",
        "with polish, up to this N: a single-swap descent with optimal geometry",
        accepted="{}",
        check=Range(0, integer=True),
    ),
    Key(
        "anneal.polish_regrafts",
        "–",
        (
            "with polish, a prune-and-regraft descent: each subtree moved onto a nearby segment "
            "where the total cost drops (strays the anneal's swaps cannot bring home)"
        ),
        default="true (`model=physiological`); else {}",
        accepted="true, false",
    ),
    Key(
        "anneal.trace_every",
        "proposals",
        "proposals between trace records",
        default="{} (`+sweep=smoke`: 50 000)",
        accepted="{}",
        check=Range(1, MAX_STEPS, integer=True),
    ),
    Key(
        "anneal.init",
        "–",
        "the initial tree: random, or the CCO tree grown from the run's generator",
        accepted="{}",
        check=OneOf(ANNEAL_INITS),
    ),
    Key(
        "anneal.parts",
        "1",
        (
            "K: the tree anneal in K parts annealed side by side ([One tree in "
            "parts](model.md#one-tree-in-parts-annealparts)); 1: the serial anneal"
        ),
        accepted="integer in [1, N/16]; > 1 needs `method=anneal`",
    ),
    Key(
        "anneal.part_phases",
        "1",
        "with parts > 1: the phases, each with two new cuts (subtrees, then terminals by place)",
        accepted="{}",
        check=Range(1, 100_000, integer=True),
    ),
    Key(
        "anneal.part_share",
        "1",
        (
            "with parts > 1: the share of a phase's proposals run in the parts; the rest on the whole "
            "tree (on 2 workers, 0.99 with a quarter more moves, `anneal.steps_at_1000` × 1.25, reached "
            "the serial costs at N = 6000 in 0.57 of its wall time)"
        ),
        accepted="{}",
        check=SHARE,
    ),
    Key(
        "terminals.path",
        "path",
        "terminal sites",
        default="{}: sites drawn uniformly in the tissue",
        accepted="a CSV of `x,y,z` in metres",
    ),
    Key(
        "terminals.fixed",
        "–",
        "the sites never move (the supply term is then off)",
        accepted="true needs `terminals.path`; not with a packing phase",
    ),
    Key(
        "method.name",
        "–",
        "how the tree is grown",
        accepted="{}",
        check=OneOf(METHODS, unknown="method", why=" (method=cco)"),
    ),
    Key(
        "method.candidates",
        "segments",
        "cco: nearest segments evaluated for each new terminal",
        accepted="{}",
        check=Range(1, integer=True),
    ),
    Key(
        "method.max_tries",
        "sites",
        "cco: consecutive rejected sites before the distance criterion shrinks",
        accepted="{}",
        check=Range(1, integer=True),
    ),
    Key("method.shrink", "1", "cco: the factor of that shrink", accepted="{}", check=SHARE),
    Key(
        "method.order",
        "–",
        "cco with `terminals.path`: sites in file order or in a seeded random order",
        accepted="{}",
        check=OneOf(("file", "random")),
    ),
    Key(
        "method.avoid_cavities",
        "–",
        (
            "cco: no new segment crosses a voxel of the tissue's cavities (the exclusion domain outside "
            "the tissue): the cheapest connection that crosses none is made, a site with none is drawn "
            "again. False: the earlier growth, bit for bit. The whole tree's territories always grow "
            "with it ([The whole tree](model.md#the-whole-tree-extension-below-the-annealed-terminals))"
        ),
        accepted="{}",
        check=BOOLEAN,
    ),
)
