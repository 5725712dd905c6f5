"""The house rules, checked: imports point down (warpcut <- envs <- agents), modules and functions stay a
readable size, ``import warpcut`` stays light, and the README's command table says what ``--help`` says."""

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("warpcut", "envs", "agents")
MAX_FILE_LINES = 600
MAX_FUNCTION_LINES = 120


def sources(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


def imported_modules(path: Path) -> set[str]:
    """Every module ``path`` imports, at any depth (including imports inside functions)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


@pytest.mark.parametrize(("package", "above"), [("warpcut", ("envs", "agents")), ("envs", ("agents",))])
def test_imports_point_down(package, above):
    upward = {
        f"{path.relative_to(ROOT)}: {name}"
        for path in sources(package)
        for name in imported_modules(path)
        if name.split(".")[0] in above
    }
    assert not upward, f"{package} must not import {above}: {sorted(upward)}"


def test_the_physics_package_never_imports_the_learning_stack():
    heavy = ("torch", "gymnasium", "rsl_rl", "tensordict")
    found = {
        f"{path.relative_to(ROOT)}: {name}"
        for path in sources("warpcut")
        for name in imported_modules(path)
        if name.split(".")[0] in heavy
    }
    assert not found, sorted(found)


def test_import_warpcut_loads_no_learning_stack():
    """``import warpcut`` and every name it exports (some load lazily) leave torch, gymnasium and rsl-rl
    unloaded."""
    code = (
        "import sys, warpcut\n"
        "for name in warpcut.__all__: getattr(warpcut, name)\n"
        "print(sorted(m for m in ('torch', 'gymnasium', 'rsl_rl') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert done.stdout.strip() == "[]", done.stdout + done.stderr


def test_the_public_face_names_what_a_script_needs():
    import warpcut

    for name in ("SimConfig", "Simulator", "CuttingTask", "Contour", "load_contour", "plan_cut", "Score"):
        assert name in warpcut.__all__ and getattr(warpcut, name) is not None
    assert warpcut.ci95([1.0, 2.0, 3.0]) > 0
    assert warpcut.paired_improvement([10.0], [5.0]).tolist() == [50.0]


def test_modules_and_functions_stay_readable():
    long_files, long_functions = [], []
    for package in PACKAGES:
        for path in sources(package):
            text = path.read_text()
            if text.count("\n") > MAX_FILE_LINES:
                long_files.append(f"{path.relative_to(ROOT)}: {text.count(chr(10))} lines")
            for node in ast.walk(ast.parse(text)):
                if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    length = node.end_lineno - node.lineno + 1
                    if length > MAX_FUNCTION_LINES:
                        long_functions.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}: {length}")
    assert not long_files, long_files
    assert not long_functions, long_functions


def readme_commands() -> dict[str, set[str]]:
    """Per command in the README's command table, the options its first cell names."""
    rows = {}
    for line in (ROOT / "README.md").read_text().splitlines():
        match = re.match(r"\| `warpcut (\w+)(.*?)` \|", line)
        if match:
            rows[match.group(1)] = set(re.findall(r"--[a-z][a-z0-9-]*", match.group(2)))
    return rows


def command_options(command) -> set[str]:
    """Every long option a command's ``--help`` lists, ``--help`` itself aside."""
    return {
        opt
        for param in command.params
        for opt in (*param.opts, *param.secondary_opts)
        if opt.startswith("--") and opt != "--help"
    }


def test_the_readme_command_table_matches_help():
    """Every command is in the table, and every option its row names is one ``--help`` lists (the row
    shows the main ones; the rest are ``--set`` keys)."""
    from agents.cli import main

    rows = readme_commands()
    assert set(rows) == set(main.commands), "README command table vs warpcut's commands"
    for name, command in main.commands.items():
        stale = sorted(rows[name] - command_options(command))
        assert not stale, f"{name}: the README names options --help does not list: {stale}"


MAX_OPTIONS = 16
"""The most options a command keeps (``--config``, ``--set`` and ``--print-config`` included, ``--help``
not): every other setting is a ``--set`` key. The commands that fan out take ``--ray`` beside their 15: where
the work runs is no setting of the job (it changes no result), so it cannot be a ``--set`` key."""


def test_every_command_keeps_at_most_16_options():
    import click

    from agents.cli import main

    counts = {}
    for name, command in main.commands.items():
        # A context under the group's, as the command line makes it: click caches a command's help
        # option from the first context it sees, and a bare one would cache it without "-h".
        parent = click.Context(main, info_name="warpcut", **main.context_settings)
        ctx = click.Context(command, parent=parent, info_name=name, **main.context_settings)
        options = [
            p for p in command.get_params(ctx) if isinstance(p, click.Option) and "--help" not in p.opts
        ]
        counts[name] = len(options)
    assert {name: n for name, n in counts.items() if n > MAX_OPTIONS} == {}
    for name in ("run", "train", "evaluate"):  # the commands with settings take the three config options
        assert {"--config", "--set", "--print-config"} <= command_options(main.commands[name]), name
    assert counts["train"] >= 12  # counted, not skipped: train has its 12 flags and the three


def test_python_dash_m_warpcut_runs_the_command_line():
    """``python -m warpcut`` reaches the CLI in agents/ through the installed entry point."""
    done = subprocess.run(
        [sys.executable, "-m", "warpcut", "contours"], capture_output=True, text=True, cwd=ROOT, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert "fls-circle" in done.stdout


def test_the_command_reference_is_every_commands_help():
    """docs/cli.md is what ``python -m agents.cli.reference`` writes: each command's ``--help`` as it is."""
    from agents.cli.reference import reference

    written = (ROOT / "docs" / "cli.md").read_text()
    assert written == reference(), "docs/cli.md is stale: python -m agents.cli.reference > docs/cli.md"


def test_no_import_circles():
    """No module of warpcut, envs or agents imports, through others, a module that imports it (imports
    inside functions count): every package reads from the bottom up."""
    modules = {}
    for package in PACKAGES:
        for path in sources(package):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            modules[name] = path
    graph = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text(), str(path))
        targets = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module:
                base = node.module
                if node.level:  # relative: from the module's package
                    package = name.split(".")[
                        : len(name.split(".")) - node.level + (path.name == "__init__.py")
                    ]
                    base = ".".join([*package, node.module])
                targets.add(base)
                targets.update(f"{base}.{alias.name}" for alias in node.names)
            elif isinstance(node, ast.Import):
                targets.update(alias.name for alias in node.names)
        graph[name] = {t for t in targets if t in modules and t != name and not name.startswith(f"{t}.")}
        graph[name] -= {t for t in graph[name] if modules[t].name == "__init__.py"}  # a package's face
    done, stack, circles = set(), [], []

    def visit(node: str) -> None:
        if node in stack:
            circles.append(stack[stack.index(node) :] + [node])
            return
        if node in done:
            return
        stack.append(node)
        for target in sorted(graph[node]):
            visit(target)
        stack.pop()
        done.add(node)

    for name in sorted(graph):
        visit(name)
    assert not circles, f"import circles: {circles[:3]}"


PROCESS_WORDS = re.compile(r"\b(sessions?|issues?) [0-9]+|\bsitting\b", re.IGNORECASE)
"""Words of a project's history, not of its software."""


def test_project_text_speaks_of_the_software_not_its_history():
    """README, docs, code, comments, tests and scripts say what the software does; the road to it is in
    version control."""
    files = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    for folder in (*PACKAGES, "tests", "scripts", "experiments"):
        files += sorted(p for p in (ROOT / folder).rglob("*") if p.suffix in (".py", ".md", ".sh", ".yaml"))
    found = [
        f"{path.relative_to(ROOT)}:{k}: {line.strip()[:80]}"
        for path in files
        for k, line in enumerate(path.read_text().splitlines(), 1)
        if PROCESS_WORDS.search(line) and path != Path(__file__)
    ]
    assert not found, "\n".join(found[:10])


def test_the_readme_is_a_short_manual():
    assert len((ROOT / "README.md").read_text().splitlines()) <= 200


def test_scripts_regenerate_the_docs_and_experiments_are_indexed():
    """scripts/ holds setup and the scripts whose figures the docs cite; every probe in experiments/ has its
    line in experiments/README.md."""
    docs = (ROOT / "README.md").read_text() + "".join(p.read_text() for p in (ROOT / "docs").rglob("*.md"))
    uncited = [
        p.name
        for p in sorted((ROOT / "scripts").iterdir())
        if p.name != "setup.sh" and f"scripts/{p.name}" not in docs
    ]
    assert not uncited, f"scripts no doc cites (move them to experiments/, or delete them): {uncited}"
    index = (ROOT / "experiments" / "README.md").read_text()
    unindexed = [p.name for p in sorted((ROOT / "experiments").glob("*.py")) if f"`{p.name}`" not in index]
    assert not unindexed, f"experiments without a line in experiments/README.md: {unindexed}"


PROMISES = {
    "A command writes one run directory": [
        "test_safety.py::test_a_run_resumes_only_as_the_command_that_made_it",
    ],
    "warpcut never writes in, resumes or deletes from": [
        "test_safety.py::test_a_folder_warpcut_did_not_mark_is_never_deleted_or_written_in",
        "test_safety.py::test_a_run_never_replaces_a_file_its_marker_does_not_list",
        "test_safety.py::test_implicit_outputs_go_only_into_a_folder_warpcut_marks",
        "test_safety.py::test_export_never_replaces_a_file_warpcut_did_not_write",
        "test_safety.py::test_a_json_output_never_replaces_a_users_file_or_writes_into_another_run",
        "test_safety.py::test_a_run_never_writes_or_deletes_through_a_link_out_of_it",
        "test_safety.py::test_a_link_made_during_a_run_is_never_written_through",
    ],
    "`--resume` continues only a run of the same command": [
        "test_safety.py::test_a_run_resumes_only_as_the_command_that_made_it",
        "test_safety.py::test_a_run_killed_before_its_summary_resumes_with_its_own_settings",
        "test_safety.py::test_evaluate_resumes_after_an_interruption_keeping_finished_policies",
        "test_safety.py::test_a_resume_stays_in_its_run_and_says_what_it_cannot_continue",
    ],
    "`--overwrite` deletes only the files the run wrote": [
        "test_safety.py::test_an_existing_run_is_refused_unless_resumed_or_overwritten",
        "test_safety.py::test_a_run_never_writes_or_deletes_through_a_link_out_of_it",
        "test_safety.py::test_overwrite_deletes_only_warpcuts_own_temporary_files",
    ],
    "A second process on the same directory": [
        "test_safety.py::test_a_run_directory_is_locked_while_a_process_writes_it",
    ],
    "Every file is written atomically": [
        "test_safety.py::test_a_failed_write_never_replaces_a_good_file",
        "test_safety.py::test_a_file_size_limit_is_one_line_and_the_run_resumes",
        "test_checkpoints.py::test_a_full_disk_while_saving_keeps_the_last_good_checkpoint",
    ],
    "Ctrl-C, SIGTERM and SIGHUP save a checkpoint": [
        "test_safety.py::test_sigterm_and_sighup_save_the_training_and_say_how_to_resume",
    ],
    "Bad input is refused on one line naming it": [
        "test_safety.py::test_bad_inputs_are_refused_before_any_work_and_leave_no_run_behind",
        "test_validation.py::test_every_config_field_refuses_a_wrong_value_by_name",
        "test_safety.py::test_every_setting_an_invocation_would_ignore_is_refused",
        "test_safety.py::test_an_unwritable_working_folder_is_named_before_any_work",
        "test_pinch_feasibility.py::test_simulate_refuses_an_infeasible_pinch_in_one_line",
        "test_pinch_feasibility.py::test_train_refuses_an_infeasible_pinch_before_any_work",
        "test_safety.py::test_deeply_nested_or_huge_inputs_are_one_line_before_any_work",
        "test_cli.py::test_a_setting_given_twice_in_one_file_or_value_is_refused",
        "test_error_causes.py::test_every_size_a_user_sets_is_checked_before_it_is_allocated",
        "test_contours.py::test_a_contour_too_dense_to_plan_is_refused_in_seconds",
        "test_contours.py::test_svg_use_bombs_are_refused_before_they_expand",
    ],
    "`docs/usage.md` has the details": [],
}
"""Each sentence of the README's "Files and safety" (by its start) and the tests that back it."""


def test_each_promise_of_the_readme_on_files_and_safety_has_its_test():
    """Every sentence of the README's "Files and safety" paragraph is listed in :data:`PROMISES` with the
    tests that check it, and each of those tests exists: a new promise needs its test."""
    readme = (ROOT / "README.md").read_text()
    start = readme.index("**Files and safety.**") + len("**Files and safety.**")
    paragraph = " ".join(readme[start:].split("\n\n")[0].split())
    sentences = [s.strip() for s in re.split(r"(?<=\.)\s+", paragraph) if s.strip()]
    unbacked = [s for s in sentences if not any(s.startswith(p) for p in PROMISES)]
    assert unbacked == [], "a promise without a test: add it to PROMISES with the tests that check it"
    for promise, tests in PROMISES.items():
        assert any(s.startswith(promise) for s in sentences), f"PROMISES names a sentence gone: {promise}"
        for test in tests:
            file, name = test.split("::")
            assert re.search(rf"^def {name}\(", (ROOT / "tests" / file).read_text(), re.M), test
