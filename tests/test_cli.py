"""`sintercond` with no arguments prints the Rojek demo table (the README's main job is `sintercond run`)."""

import subprocess
import sys

import pytest

from sintercond import cli


def test_demo_table_has_paper_values(capsys):
    assert cli.main([]) == 0
    out = capsys.readouterr().out
    # Rojek et al. 2022: a = 0.741466 mm (h = 0.2 mm), a = 0.419186 mm and K = 0.276035 W/K (h = 0.06 mm)
    assert "0.741466" in out and "0.419186" in out and "0.276035" in out
    assert len([line for line in out.splitlines() if line.startswith("  1.000000")]) == len(cli.ROJEK_CASES_MM)


def test_demo_rejects_bad_kappa(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["demo", "--kappa", "-3"])
    assert exc.value.code == 2
    assert "--kappa must be finite and > 0" in capsys.readouterr().err


@pytest.mark.slow
def test_console_script_runs():
    # the installed entry point, as a user runs it
    result = subprocess.run([sys.executable, "-m", "sintercond.cli", "demo"], capture_output=True, text=True, check=True)
    assert "K_rojek" in result.stdout


@pytest.mark.slow
def test_effective_on_a_powder_bed(tmp_path, capsys):
    # before: "no particle reaches the box faces" on every powder bed
    scene = tmp_path / "bed.toml"
    scene.write_text(
        '[packing]\nkind = "powder_bed"\nlateral_size = 300e-6\nheight = 200e-6\ndiameter_range = [45e-6, 90e-6]\n'
        'sinter_swelling = 0.02\n[material]\ndensity = 4430.0\nspecific_heat = 560.0\nconductivity = 12.6\n'
        '[conduction]\nlaw = "rojek"\n[initial]\ntemperature = 300.0\n'
        '[run]\nduration = 1e-3\noutput_every = 5\ncheckpoint_every = 5\n')
    assert cli.main(["effective", str(scene)]) == 0
    out = capsys.readouterr().out
    k_star = float(out.split(":")[1].split()[0])
    assert "k* = Q L / (A dT)" in out and "mean surface height" in out
    # a sintered bed conducts, far below the solid and above nothing
    assert 0.02 * 12.6 < k_star < 0.6 * 12.6


@pytest.mark.parametrize("argv, code, stream, text", [
    (["scenes"], 0, "stdout", "ti6al4v_preheating_bed"),
    (["run", "nowhere.toml"], 2, "stderr", "scene file 'nowhere.toml' does not exist"),
    (["demo", "--kappa", "-3"], 2, "stderr", "--kappa must be finite and > 0"),
    (["--help"], 0, "stdout", "usage: sintercond"),
])
def test_the_command_ends_with_its_exit_code_and_all_its_output(argv, code, stream, text):
    """``cli.entry`` (the installed ``sintercond``) leaves through ``os._exit`` to skip the ~0.3 s of jaxlib's
    shutdown: its exit code and every line it printed must still come out."""
    script = f"import sys; sys.argv = ['sintercond', *{argv!r}]; from sintercond.cli import entry; entry()"
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert result.returncode == code
    assert text in getattr(result, stream)
    if argv == ["scenes"]:
        from sintercond.scene import builtin_scenes

        assert all(name in result.stdout for name in builtin_scenes())  # the last line too: flushed
