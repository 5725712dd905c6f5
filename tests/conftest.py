"""Shared test set-up: every device Warp sees (CPU always; CUDA when a GPU is present)."""

from __future__ import annotations

import os

import pytest
import warp as wp
from hypothesis import settings

# Hypothesis profiles, chosen by HYPOTHESIS_PROFILE: "ci" (the default: few examples, the same ones every run)
# or "long" for a real fuzzing session: HYPOTHESIS_PROFILE=long pytest tests/test_fuzz_contours.py
settings.register_profile("ci", max_examples=25, deadline=None, derandomize=True, database=None)
settings.register_profile("long", max_examples=1000, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

wp.config.log_level = wp.LOG_WARNING
wp.init()

DEVICES = ["cpu"] + (["cuda"] if wp.is_cuda_available() else [])


@pytest.fixture(params=DEVICES)
def device(request) -> str:
    """Run the test once per available Warp device."""
    return request.param


@pytest.fixture
def unbounded_noise(monkeypatch):
    """Process noise beyond :data:`warpcut.sim.config.NOISE_STD_MAX_MM` accepted: how a test blows a sheet up
    (the bound refuses it from users)."""
    import math

    import warpcut.sim.config

    monkeypatch.setattr(warpcut.sim.config, "NOISE_STD_MAX_MM", math.inf)


@pytest.fixture(scope="module")
def one_torch_thread():
    """Tiny MLPs gain nothing from threads, and threads slow to a crawl on a busy 2-core machine (use it
    per module: ``pytestmark = pytest.mark.usefixtures("one_torch_thread")``)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


SLOW_TESTS = frozenset(
    (
        "tests/test_checkpoints.py::test_a_checkpoint_describes_its_own_policy",
        "tests/test_cli.py::test_advice_names_each_setting_as_the_command_gives_it",
        "tests/test_cli.py::test_algo_ppo_makes_the_actions_discrete_unless_set",
        "tests/test_cli.py::test_evaluate_two_contours_two_trials_writes_table_json",
        "tests/test_cli.py::test_print_config_is_yaml_that_config_reads_back_to_the_same_job",
        "tests/test_cli.py::test_run_end_to_end_on_a_tiny_budget",
        "tests/test_cli.py::test_train_apg_runs_and_refuses_discrete_actions",
        "tests/test_cli.py::test_train_es_trains_its_feedback_path_and_refuses_a_population_that_does_not_fit",
        "tests/test_cli.py::test_train_ppo_trains_discrete_moves_unless_told",
        "tests/test_cli.py::test_train_resume_export_and_evaluate_with_checkpoints",
        "tests/test_cli.py::test_warp_starts_quietly_unless_asked",
        "tests/test_cli_bench.py::test_bench_reports_the_default_learners_and_ppos_training_beside_the_simulator",
        "tests/test_cli_bench.py::test_bench_writes_the_documented_json",
        "tests/test_cli_optimize.py::test_a_run_directorys_config_runs_the_same_job_and_resume_keeps_its_settings",
        "tests/test_cli_robustness.py::test_robustness_of_a_randomised_run_end_to_end",
        "tests/test_cli_simulate.py::test_console_script_runs",
        "tests/test_cluster.py::test_a_unit_runs_torch_on_the_drivers_threads_and_the_simulator_on_its_cpu",
        "tests/test_cluster.py::test_a_unit_whose_worker_dies_is_retried_and_the_run_completes",
        "tests/test_cluster.py::test_an_address_nobody_answers_at_is_one_line_naming_it",
        "tests/test_cluster.py::test_an_interrupted_fanned_out_evaluate_resumes_to_the_same_rows",
        "tests/test_cluster.py::test_ctrl_c_cancels_the_units_still_running",
        "tests/test_cluster.py::test_evaluate_gives_the_same_rows_and_policies_on_two_workers",
        "tests/test_cluster.py::test_robustness_gives_the_same_report_on_two_workers",
        "tests/test_cluster.py::test_sigterm_stops_a_fanned_out_evaluate_and_its_ray_instance",
        "tests/test_cluster.py::test_the_sharded_env_steps_as_the_whole_batch_even_when_an_actor_dies",
        "tests/test_cluster.py::test_without_ray_the_command_never_imports_ray",
        "tests/test_contours.py::test_a_contour_too_dense_to_plan_is_refused_in_seconds",
        "tests/test_contours.py::test_coarse_grid_blames_the_resolution_for_no_pinch_point",
        "tests/test_dagger.py::test_a_dagger_generalist_trains_resumes_exactly_and_plays_everywhere",
        "tests/test_dagger.py::test_a_dataset_resumes_and_grows_keeping_its_teachers",
        "tests/test_dagger.py::test_teachers_builds_a_dataset_a_contour_a_unit",
        "tests/test_dagger.py::test_teachers_near_a_student_start_from_its_moves_and_a_heavy_tether_keeps_them",
        "tests/test_dagger.py::test_the_suite_like_kinds_are_drawn_where_asked_and_named_by_their_specs",
        "tests/test_envs.py::test_a_generated_contour_is_made_by_its_name",
        "tests/test_error_causes.py::test_bench_names_the_option_of_the_batch_too_big",
        "tests/test_es_policy.py::test_a_resumed_es_run_ends_with_the_weights_of_an_uninterrupted_one",
        "tests/test_es_policy.py::test_an_es_run_stopped_mid_cut_resumes_as_if_never_stopped",
        "tests/test_es_policy.py::test_es_learns_a_neural_policy_that_beats_a_still_grasp",
        "tests/test_es_policy.py::test_es_refuses_what_it_cannot_train",
        "tests/test_es_policy.py::test_es_trains_the_feedback_path_and_its_exports_play_it",
        "tests/test_export.py::test_a_run_directory_exports_the_chosen_candidates_policy",
        "tests/test_export.py::test_an_evaluate_directory_exports_every_contours_policy_with_metadata",
        "tests/test_export.py::test_the_default_trainings_policy_runs_on_the_default_env",
        "tests/test_export.py::test_the_exported_policy_runs_in_onnxruntime_on_the_env_its_metadata_makes",
        "tests/test_fuzz_physics.py::test_env_observations_and_rewards_are_never_nan",
        "tests/test_generalist.py::test_a_generalist_refines_the_shipped_one_by_its_name",
        "tests/test_generalist.py::test_a_generalist_run_resumes_to_train_longer",
        "tests/test_generalist.py::test_a_generalist_that_validates_no_better_than_holding_still_holds_still",
        "tests/test_generalist.py::test_a_generalist_trains_over_generated_contours_into_its_run_directory",
        "tests/test_generalist.py::test_a_reward_relative_to_no_tension_makes_the_episode_cost_the_error_over_no_tensions",
        "tests/test_generalist.py::test_evaluate_and_run_play_a_generalist_with_members",
        "tests/test_generalist.py::test_every_command_plays_a_generalist_zero_shot",
        "tests/test_generalist.py::test_generated_contours_are_named_and_resolved_by_their_specs",
        "tests/test_generalist.py::test_the_guarded_generalist_chooses_the_gain_on_its_moves_it_validates_best_with",
        "tests/test_generalist.py::test_the_guarded_generalist_plays_where_it_validates_best_and_else_holds_still",
        "tests/test_generate.py::test_every_kind_is_drawn_and_each_contour_is_resolvable_and_plannable",
        "tests/test_generate.py::test_the_same_seed_gives_the_same_contours_and_more_keeps_the_first",
        "tests/test_generate.py::test_the_splits_never_share_a_contour",
        "tests/test_gps.py::test_a_resumed_gps_run_ends_as_an_uninterrupted_one",
        "tests/test_gps.py::test_a_run_saved_before_the_correction_was_centred_is_refused_on_resume_in_one_line",
        "tests/test_gps.py::test_a_run_stopped_while_its_teacher_is_optimised_resumes_with_its_teacher",
        "tests/test_gps.py::test_an_exported_student_runs_on_the_env_its_metadata_makes",
        "tests/test_gps.py::test_evaluates_grad_column_plays_the_teachers_plans_as_it_would_have_found_them",
        "tests/test_gps.py::test_the_correction_trains_on_randomised_sheets_and_is_selected_on_both",
        "tests/test_gps.py::test_the_exports_carry_the_plan",
        "tests/test_gradient_methods.py::test_es_learns_feedback_gains_that_beat_a_still_grasp",
        "tests/test_gradient_methods.py::test_the_usage_guides_closed_loop_example_runs",
        "tests/test_gradients.py::test_the_usage_guides_gradient_example_runs",
        "tests/test_gym_conventions.py::test_a_users_own_envs_package_does_not_hide_the_env",
        "tests/test_pipeline.py::test_the_readme_python_examples_run",
        "tests/test_planning.py::test_empty_feasible_region_names_the_contour",
        "tests/test_policies.py::test_ppo_learns_to_lift_the_parabola",
        "tests/test_ppo_speed.py::test_importing_agents_before_torch_shortens_openmp_spinning",
        "tests/test_recording.py::test_evaluate_writes_the_comparison_plot_and_recording",
        "tests/test_recording.py::test_replay_web_prints_the_recording_url_and_stops_the_server_on_a_signal",
        "tests/test_recording.py::test_replay_web_serves_with_rerun_and_frees_its_ports",
        "tests/test_recording.py::test_the_recorder_process_finishes_the_file_when_the_stepping_process_dies",
        "tests/test_render.py::test_rgb_array_shows_the_sheet_contour_grasp_and_the_cut_so_far",
        "tests/test_render.py::test_the_vector_env_renders_its_first_envs",
        "tests/test_robustness.py::test_a_randomised_run_compares_its_pinch_candidates_on_the_nominal_sheet",
        "tests/test_robustness.py::test_a_run_cut_in_another_order_is_paired_with_no_tension_in_that_order",
        "tests/test_robustness.py::test_grad_plays_its_plan_at_every_value_and_is_optimised_once",
        "tests/test_robustness.py::test_optimised_plans_are_played_as_methods_closed_loop_included",
        "tests/test_robustness.py::test_resolution_study_skips_a_mesh_too_coarse_for_the_contour",
        "tests/test_safety.py::test_a_contour_name_never_becomes_a_path_outside_the_run",
        "tests/test_safety.py::test_a_file_size_limit_is_one_line_and_the_run_resumes",
        "tests/test_safety.py::test_a_recording_on_a_full_disk_keeps_the_earlier_one",
        "tests/test_safety.py::test_a_run_killed_before_its_summary_resumes_with_its_own_settings",
        "tests/test_safety.py::test_a_run_never_replaces_a_file_its_marker_does_not_list",
        "tests/test_safety.py::test_a_run_resumes_only_as_the_command_that_made_it",
        "tests/test_safety.py::test_evaluate_resumes_after_an_interruption_keeping_finished_policies",
        "tests/test_safety.py::test_export_never_replaces_a_file_warpcut_did_not_write",
        "tests/test_safety.py::test_export_of_a_run_stopped_before_it_chose_a_candidate",
        "tests/test_safety.py::test_run_pipeline_resumes_its_candidates",
        "tests/test_safety.py::test_sigterm_and_sighup_save_the_training_and_say_how_to_resume",
        "tests/test_safety.py::test_train_refuses_an_existing_run_and_stops_on_sigterm_with_a_checkpoint",
    )
)
"""The tests (parametrised ones by their function) that each took over about 1.4 s, their fixtures
included, in a full run on a quiet 2-core machine (``pytest --durations=80``), besides those marked ``slow``
where they are defined: ``pytest -m "not slow"`` is the quick tier, every module still checked."""


def pytest_collection_modifyitems(config, items):
    """Mark :data:`SLOW_TESTS` ``slow``."""
    for item in items:
        if item.nodeid.split("[")[0] in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)
