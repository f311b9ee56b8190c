"""The paper's published figures of merit (potential field method for the upper extremity, Sci Rep;
../shared/paper/), the numbers exubio's validation report is compared with. Plain data."""
from __future__ import annotations

PAPER: dict = {
    "citation": "Potential field method for upper-extremity motion reconstruction (Sci Rep), "
                "results: sensitivity (Fig. 2), Table 1, Fig. 3-5",
    "table1": {
        "abduction": {"frames": 4541, "duration_s": 25, "pf_wall_s": 18, "ls_wall_s": 435,
                      "max_mean_residual_mm": 18.0, "sd_at_max_mean_mm": 12.0,
                      "max_residual_mm": 45.6, "max_residual_marker": "TS1",
                      "max_rmse_mm": 28.4, "max_rmse_marker": "GH"},
        "flexion": {"frames": 4940, "duration_s": 25, "pf_wall_s": 16, "ls_wall_s": 490,
                    "max_mean_residual_mm": 18.7, "sd_at_max_mean_mm": 12.6,
                    "max_residual_mm": 49.0, "max_residual_marker": "GH",
                    "max_rmse_mm": 28.7, "max_rmse_marker": "GH"},
        "sier": {"frames": 96001, "duration_s": 30, "pf_wall_s": 32, "ls_wall_s": 5057,
                 "max_mean_residual_mm": 4.0, "sd_at_max_mean_mm": 5.9,
                 "max_residual_mm": 26.5, "max_residual_marker": "GH",
                 "max_rmse_mm": 11.8, "max_rmse_marker": "GH"},
    },
    "pf_ms_per_frame": 2.5,
    "ls_ms_per_frame": 82.6,
    "sier_gh_axial_rmse_deg": {"pf": 3.69, "ls": 3.13},
    "sier_gh_marker_rmse_mm": {"pf_x": 1.66, "ls_x": 1.59, "pf_z": 1.56, "ls_z": 1.62},
    "pf_ls_max_joint_rmse_deg": 1.87,
    "pf_ls_max_marker_rmse_mm": 0.37,
    "pf_ls_rmse_deg_by_motion": {"abduction": 1.44, "flexion": 1.67},
    "sensitivity": {"stiffness_n_per_m": [10, 10000], "ratio_s": [0.01, 10], "runs": 32,
                    "chosen_stiffness_n_per_m": 1500, "chosen_damping_ns_per_m": 300,
                    "finding": "deflections converge for c > 1000 N/m; k = 10 s gives large "
                               "spring-damper forces and inaccuracies"},
    "hardware": "one core of a 3.30 GHz desktop CPU, 32 GB RAM (SIMPACK; LS in MATLAB fmincon)",
}
