"""Same bits on any x86-64 machine: the numerics are pinned (mani_skill_softvt/provenance/numerics.py), and what
the benchmark computes under them matches the committed golden fingerprints.

The goldens (tests/golden/fingerprints.json) were made under the pins on one machine kind and name
the kinds they have passed on. A failure here on another kind means some dispatch is still the
host's: the message says which part of the computation (physics, cameras, touch, policy) moved.
"""

import json
import os
import re
from pathlib import Path

import pytest

from mani_skill_softvt import fingerprints as F
from mani_skill_softvt.provenance import numerics as N
from mani_skill_softvt.parallel import run_tasks
from softvt_campaign import fingerprints as DP

GOLDEN = json.loads((Path(__file__).parent / "golden" / "fingerprints.json").read_text())
EPYC = {"cpu": "AMD EPYC", "cpu-isa": "AVX512 avx512_bf16 avx512f avx2 fma"}
XEON = {"cpu": "Intel(R) Xeon(R) Processor", "cpu-isa": "AVX512 amx_bf16 avx512_bf16 avx512f avx2 fma"}


def _pinned_record(mkl_cbwr: str, parts: list | None = None) -> dict:
    """A record made on an AMD EPYC under pins named x86-64-v3 (today's carry their parts, earlier ones none)."""
    numerics = {"name": "x86-64-v3", "pinned": True, "environment": {"MKL_CBWR": mkl_cbwr}}
    return {"receipt": {"stack": EPYC, "numerics": numerics if parts is None else {**numerics, "parts": parts}}}


def _pinned_variables(queue):
    got = N.resolved()
    return N.chosen().name, {v: os.environ.get(v) for v in ("ATEN_CPU_CAPABILITY", "OPENBLAS_CORETYPE")}, \
        got["torch_cpu_capability"] if got["pinned"] or got["name"] == "native" else "not pinned in full"


def _vml_kernels_in_a_worker(queue):
    """VML's kernel family in a worker process, before and after VML's first call, and after the
    variable changes (VML keeps the choice of its first call: what resolved() reads is what ran)."""
    import torch

    torch.rand(8) ** 0.5
    first = N.vml_cpu_type()
    os.environ["MKL_VML_DEBUG_CPU_TYPE"] = "5" if first == 1 else "1"
    return os.environ.get(N.NUMERICS_ENV), first, N.vml_cpu_type(), N.resolved()["mkl_vml_cpu_type"]


def _released_onednn(queue):
    N.release("onednn")
    got = N.resolved()
    return os.environ.get("ONEDNN_MAX_CPU_ISA"), got["released"], got["pinned"], os.environ.get("ATEN_CPU_CAPABILITY")


# ------------------------------------------------------------------------------------ the choice


def test_numerics_names_parse_and_bad_ones_say_what_to_write():
    assert N.parse("x86-64-v3").parts == tuple(N.PARTS)
    assert N.parse("native").parts == () and N.parse("native").warp_cpu_compiler_flags is None
    assert N.parse("x86-64-v3:warp,aten").parts == ("warp", "aten")
    # One spelling per choice: the parts in their canonical order; all of them is the full pin.
    assert N.parse("x86-64-v3:aten,warp").name == "x86-64-v3:warp,aten"
    assert N.parse("x86-64-v3:" + ",".join(reversed(N.PARTS))).name == "x86-64-v3"
    assert N.parse("x86-64-v3:aten").warp_cpu_compiler_flags is None
    with pytest.raises(ValueError, match="SOFTVT_NUMERICS='avx512'.*'x86-64-v3'"):
        N.parse("avx512")
    with pytest.raises(ValueError, match="unknown part.*blas"):
        N.parse("x86-64-v3:blas")


def test_the_package_import_pinned_this_process_and_every_library_took_it():
    got = N.resolved()
    assert got["name"] == N.PINNED and got["pinned"], got
    assert got["warp_cpu_compiler_flags"] == N.WARP_PINNED_FLAGS and "-march=native" not in got["warp_cpu_compiler_flags"]
    assert got["torch_cpu_capability"] == "AVX2" and not got["numpy_avx512"] and not got["opencv_avx512"]
    assert got["openblas_core"] == "Haswell"


def test_a_library_loaded_before_the_pin_counts_only_where_its_variables_did_not_already_hold_it():
    numerics = N.parse(N.PINNED)
    pinned = numerics.environment()
    # The shell's variables: NumPy and torch chose their kernels unpinned.
    assert N.loaded_unpinned(["numpy", "torch"], {}, numerics) == ["numpy", "torch"]
    # A Ray worker: its runtime_env set every pin before Ray imported NumPy.
    assert N.loaded_unpinned(["numpy", "torch", "cv2"], pinned, numerics) == []
    # One of NumPy's variables missing (OpenBLAS's kernel family): NumPy may have chosen otherwise.
    assert N.loaded_unpinned(["numpy"], {k: v for k, v in pinned.items() if k != "OPENBLAS_CORETYPE"}, numerics) == ["numpy"]
    # A part the choice does not pin cannot be missed.
    assert N.loaded_unpinned(["numpy"], {}, N.parse(f"{N.PINNED}:warp")) == []


@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
def test_a_worker_starts_pinned_and_a_native_reproduction_unpins_it(monkeypatch):
    (pinned,) = [v for k, v in run_tasks(_pinned_variables, [()], 1) if k == "result"]
    assert pinned == ("x86-64-v3", {"ATEN_CPU_CAPABILITY": "avx2", "OPENBLAS_CORETYPE": "Haswell"}, "AVX2")
    # A record made before the pins replays under each library's own choice, whatever this process has.
    # The shell's own settings, not the pins (this workplace's AMD EPYC machines set OPENBLAS_CORETYPE=Haswell).
    shell = json.loads(os.environ[N.ORIGINAL_ENV])
    (native,) = [v for k, v in run_tasks(_pinned_variables, [()], 1, numerics="native") if k == "result"]
    assert native[:2] == ("native", {"ATEN_CPU_CAPABILITY": shell.get("ATEN_CPU_CAPABILITY"),
                                     "OPENBLAS_CORETYPE": shell.get("OPENBLAS_CORETYPE")})
    assert os.environ["ATEN_CPU_CAPABILITY"] == "avx2"  # this process's own pins are as they were
    # A part pinned alone: the others are the shell's in the worker, and its records are not "pinned".
    (part,) = [v for k, v in run_tasks(_pinned_variables, [()], 1, numerics="x86-64-v3:openblas") if k == "result"]
    assert part[:2] == ("x86-64-v3:openblas", {"ATEN_CPU_CAPABILITY": shell.get("ATEN_CPU_CAPABILITY"),
                                               "OPENBLAS_CORETYPE": "Haswell"})


def test_a_bfloat16_training_releases_onednn_alone_and_says_so():
    # In a process of its own (oneDNN chooses once per process): the shell had no ONEDNN_MAX_CPU_ISA.
    (got,) = [v for k, v in run_tasks(_released_onednn, [()], 1) if k == "result"]
    assert got == (None, ["onednn"], False, "avx2")
    with pytest.raises(ValueError, match="unknown part"):
        N.release("blas")


def test_a_record_names_its_numerics_and_a_reproduction_is_told_about_the_machine():
    epyc, xeon = EPYC, XEON
    old = {"receipt": {"stack": epyc}}  # made before the pins, on a machine that set OPENBLAS_CORETYPE
    assert N.numerics_of(old) == "x86-64-v3:openblas" and N.numerics_of({"receipt": {"stack": xeon}}) == "native"
    assert "of the kind that made them" in N.reproduction_note(old, {**epyc, "cpu-isa": "AVX2 avx512_bf16 avx512f avx2 fma "
                                                                       "onednn_max=AVX2"})
    assert "their outcomes may differ here" in N.reproduction_note(old, xeon)
    assert "do not name their machine" in N.reproduction_note({"receipt": {}}, xeon)
    pinned = {"receipt": {"stack": epyc, "numerics": {"name": "x86-64-v3", "pinned": True, "parts": list(N.PARTS)}}}
    assert N.numerics_of(pinned) == "x86-64-v3" and N.reproduction_note(pinned, xeon) is None


def test_mkl_is_pinned_to_the_branch_it_keeps_alike_across_cpu_vendors_and_earlier_records_replay_as_made():
    """MKL_CBWR=AVX2 is MKL's Intel-only branch (elsewhere it falls back to AUTO): the pins take
    COMPATIBLE. A record of the earlier pins names the same numerics but MKL_CBWR=AVX2 in its
    environment; it is replayed under those (mkl-avx2), and its reproduction says where it holds."""
    assert N.parse(N.PINNED).environment()["MKL_CBWR"] == "COMPATIBLE"
    assert N.parse(N.PINNED_MKL_AVX2).environment()["MKL_CBWR"] == "AVX2"
    assert N.parse(N.PINNED_MKL_AVX2).name == N.PINNED_MKL_AVX2 and "mkl" not in N.parse(N.PINNED_MKL_AVX2).parts
    with pytest.raises(ValueError, match="mkl and mkl-avx2"):
        N.parse("x86-64-v3:mkl,mkl-avx2")
    epyc, xeon = EPYC, XEON
    earlier, today = _pinned_record("AVX2"), _pinned_record("COMPATIBLE", list(N.PARTS))
    assert N.numerics_of(earlier) == N.PINNED_MKL_AVX2 and N.numerics_of(today) == N.PINNED
    policy = {**earlier, "policy_sha256": "ab" * 32}  # a trained policy's record (the expert's hold anywhere)
    assert "may differ" in N.reproduction_note(policy, xeon) and N.reproduction_note(earlier, xeon) is None
    assert "same vendor" in N.reproduction_note(policy, {**epyc, "cpu": "AMD EPYC 9R14"})
    assert N.reproduction_note(today, xeon) is None


def test_a_policys_keypoints_take_no_blas_under_the_pins_and_earlier_records_replay_through_mkls_gemv():
    """MKL's GEMV on AMD ignores MKL_CBWR, so the spatial softmax's expected coordinates are ATen's
    reduction under the pins: the same keypoints up to rounding, and no MKL BLAS call in a
    policy's inference. Records of the earlier pins (named x86-64-v3, without "parts") replay as made."""
    import torch

    from softvt_campaign.baselines.networks import SpatialSoftmax

    assert "keypoints" in N.parse(N.PINNED).parts and N.parse(N.PINNED_GEMV_KEYPOINTS).name == N.PINNED_GEMV_KEYPOINTS
    assert "keypoints" not in N.parse(N.PINNED_GEMV_KEYPOINTS).parts and N.resolved()["parts"] == list(N.PARTS)
    x = torch.randn(2, 4, 6, 5, generator=torch.Generator().manual_seed(0))
    pinned = SpatialSoftmax()(x)
    w = torch.softmax(x.reshape(2, 4, 30).double(), -1)
    grid_y, grid_x = torch.meshgrid(torch.linspace(-1, 1, 6, dtype=torch.float64),
                                    torch.linspace(-1, 1, 5, dtype=torch.float64), indexing="ij")
    exact = torch.cat([w @ grid_x.reshape(-1), w @ grid_y.reshape(-1)], -1)
    # float32 sums of 30 terms in [-1, 1] with weights summing to 1: within a few ulp of 1.
    assert torch.allclose(pinned.double(), exact, atol=30 * 2 ** -24, rtol=0)
    epyc, xeon = EPYC, XEON
    earlier, today = _pinned_record("COMPATIBLE"), _pinned_record("COMPATIBLE", list(N.PARTS))
    assert N.numerics_of(earlier) == N.PINNED_GEMV_KEYPOINTS and N.numerics_of(today) == N.PINNED
    policy = {**earlier, "policy_sha256": "ab" * 32}
    assert "GEMV" in N.reproduction_note(policy, xeon) and "may differ" in N.reproduction_note(policy, xeon)
    assert "same vendor" in N.reproduction_note(policy, epyc) and N.reproduction_note(today, xeon) is None


# The maths functions whose float32 and float64 kernels torch hands to MKL's vector maths (ATen's vml.h)
# and a policy or its training calls: the timestep embedding, the DDIM and DDPM square roots.
VML_FUNCTIONS = ("Exp", "Sin", "Cos", "Sqrt", "Ln", "Tanh")
APPROXIMATIONS = re.compile(r"\s(v?(rcp|rsqrt)(ps|ss)|f2xm1|fyl2x|fyl2xp1|fsin|fcos|fsincos|fptan|fpatan)\s")


def _vml_kernels(kind: str) -> dict[str, str]:
    """{name: disassembly} of MKL's vector-maths kernels of ``kind`` (``E2``: SSE2, ``EX``: SSE4.2) for
    :data:`VML_FUNCTIONS`, from the copy of MKL linked into torch (each symbol's code runs to the next
    exported one's, its local helpers with it)."""
    import subprocess

    import torch

    lib = Path(torch.__file__).parent / "lib" / "libtorch_cpu.so"
    try:
        table = subprocess.run(["nm", "-D", "--defined-only", str(lib)], capture_output=True, text=True, check=True).stdout
        subprocess.run(["objdump", "--version"], capture_output=True, check=True)
    except (OSError, subprocess.CalledProcessError) as e:
        pytest.skip(f"binutils (nm, objdump) could not read {lib} ({e}): it is needed to read MKL's kernels")
    addresses = sorted({int(line.split()[0], 16) for line in table.splitlines() if line.split()[1:2] == ["T"]})
    wanted = {line.split()[2]: int(line.split()[0], 16) for line in table.splitlines()
              if re.fullmatch(rf"mkl_vml_kernel_[sd]({'|'.join(VML_FUNCTIONS)})_{kind}HAynn", line.split()[-1])}
    if not wanted:
        pytest.skip(f"{lib} holds no MKL vector-maths kernels (a torch without MKL calls none)")
    out = {}
    for name, start in wanted.items():
        stop = addresses[addresses.index(start) + 1]
        out[name] = subprocess.run(["objdump", "-d", "--no-show-raw-insn", f"--start-address={start:#x}",
                                    f"--stop-address={stop:#x}", str(lib)], capture_output=True, text=True,
                                   check=True).stdout
    return out


# A VML kernel that differs across vendors shows in the goldens below, which stay in the default run.
@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
def test_mkls_vector_maths_run_kernels_without_vendor_defined_instructions_under_the_pins():
    """MKL's vector maths (VML), which torch's float32 exp, sin, cos and square roots call, ignores
    MKL_CBWR=COMPATIBLE: it ran its SSE4.2 kernels, whose square root starts from rsqrtps, an
    approximation whose bits each CPU vendor defines (Intel's and AMD's differ): the likely cause of a
    policy's action chunk moving by 1e-6 between the two (2026-12-05). The pins set VML's CPU type
    to its SSE2 kernels (``vml``), which hold no approximation instruction and call nothing outside
    themselves but VML's mode and error handlers."""
    import torch

    assert N.parse(N.PINNED).environment()["MKL_VML_DEBUG_CPU_TYPE"] == "1"
    sse2, sse42 = _vml_kernels("E2"), _vml_kernels("EX")
    assert len(sse2) == 2 * len(VML_FUNCTIONS)  # float32 and float64, each function's
    assert not {n: APPROXIMATIONS.findall(code) for n, code in sse2.items() if APPROXIMATIONS.search(code)}
    assert re.search(r"\ssqrtps\s", sse2["mkl_vml_kernel_sSqrt_E2HAynn"])  # the maths itself is in the range
    for name, code in sse2.items():
        starts = [int(m, 16) for m in re.findall(r"^\s*([0-9a-f]+):", code, re.M)]
        for target, label in re.findall(r"(?:call|j[a-z]+)\s+([0-9a-f]+) <([^>]+)>", code):
            inside = starts[0] <= int(target, 16) <= starts[-1]
            assert inside or re.fullmatch(r"mkl_vml_kernel_(GetMode|[sd]Error)@plt", label), (name, label)
    assert APPROXIMATIONS.search(sse42["mkl_vml_kernel_sSqrt_EXHAynn"])  # what the pins before ran
    torch.rand(8) ** 0.5  # VML chooses its kernels at its first call
    assert N.vml_cpu_type() == 1 == N.resolved()["mkl_vml_cpu_type"], "MKL's vector maths run other kernels than the pins'"


@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
def test_records_of_the_pins_before_vml_replay_under_them_and_a_policys_per_vendor():
    """A record of the full pins before 2026-12-06 names parts without ``vml``: it is read as those pins
    with VML's own detection (``vml-detect``, the variable set empty, which MKL reads as no override,
    so that a Ray worker can carry it), its worker runs VML's detected kernels, and a reproduction of a
    policy's record on the other CPU vendor says its outcomes may differ (the expert's hold)."""
    earlier = _pinned_record("COMPATIBLE", [p for p in N.PARTS if p != "vml"])
    policy, today = {**earlier, "policy_sha256": "ab" * 32}, _pinned_record("COMPATIBLE", list(N.PARTS))
    assert N.numerics_of(earlier) == N.PINNED_VENDOR_VML and "vml" not in N.parse(N.PINNED_VENDOR_VML).parts
    assert N.environment(N.PINNED_VENDOR_VML)["MKL_VML_DEBUG_CPU_TYPE"] == ""
    assert all(v is not None for v in N.environment(N.PINNED_VENDOR_VML).values())  # a Ray worker can be given it
    with pytest.raises(ValueError, match="vml and vml-detect"):
        N.parse("x86-64-v3:vml,vml-detect")
    assert "rsqrtps" in N.reproduction_note(policy, XEON) and "may differ" in N.reproduction_note(policy, XEON)
    assert "same vendor" in N.reproduction_note(policy, {**EPYC, "cpu": "AMD EPYC 9R14"})
    assert N.reproduction_note(earlier, XEON) is None  # the expert
    assert N.reproduction_note({**today, "policy_sha256": "ab" * 32}, XEON) is None
    released = {"receipt": {**policy["receipt"], "numerics": {**policy["receipt"]["numerics"], "released": ["onednn"]}}}
    assert "not pinned in full" in N.reproduction_note({**policy, **released}, {**EPYC, "cpu": "AMD EPYC 9R14"})
    (pinned,) = [v for k, v in run_tasks(_vml_kernels_in_a_worker, [()], 1) if k == "result"]
    (before,) = [v for k, v in run_tasks(_vml_kernels_in_a_worker, [()], 1, numerics=N.PINNED_VENDOR_VML)
                 if k == "result"]
    assert pinned == (N.PINNED, 1, 1, 1)
    # VML's own detection (SSE4.2 or wider kernels on any x86-64-v3 CPU), kept past a later change of the variable.
    assert before[0] == N.PINNED_VENDOR_VML and before[1] != 1 and before[1] == before[2] == before[3]


def test_the_fingerprint_script_writes_and_compares_a_policys_golden(tmp_path, monkeypatch):
    import importlib.util

    spec = importlib.util.spec_from_file_location("fingerprint_script", Path(__file__).parents[1] / "scripts" /
                                                  "fingerprint.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    monkeypatch.setattr(script, "CASES", {"dp_inference": lambda: {"episode": "abc"}})
    monkeypatch.setattr(script, "software_stack", lambda: {"cpu": "AMD EPYC 9R14", "cpu-isa": "AVX2 avx2 fma"})
    golden = tmp_path / "golden.json"
    pinned = {"pinned": True, "name": N.PINNED, "warp_cpu_compiler_flags": "flags"}
    assert script.write_golden(golden, {"numerics": pinned, "dp_inference": {"episode": "abc"}}) == []
    assert list(json.loads(golden.read_text())["cases"]) == ["dp_inference"]
    assert script.main(["--cases", "dp_inference", "--compare", str(golden)]) == 0
    monkeypatch.setattr(script, "software_stack", lambda: XEON)  # another vendor: the same golden
    assert script.write_golden(golden, {"numerics": pinned, "dp_inference": {"episode": "abc"}}) == []
    assert len(json.loads(golden.read_text())["cases"]["dp_inference"]["passed_on"]) == 2


def test_two_traces_of_a_policys_inference_are_compared_at_their_first_differing_call():
    """The tool that is to find the vendor difference (scripts/fingerprint.py --trace-compare): the
    first call whose name or output differs, a shorter trace differing where it ends."""
    from softvt_campaign.fingerprints import first_difference

    a = ["conv2d:aa", "group_norm:bb", "mish:cc"]
    assert first_difference(a, list(a)) is None
    assert first_difference(a, ["conv2d:aa", "group_norm:bx", "mish:cc"]) == 1
    assert first_difference(a, a[:2]) == 2
    trace = json.loads((Path(__file__).parent / "golden" / "dp_inference_trace_intel.json").read_text())
    assert trace["numerics"] == N.PINNED and len(trace["calls"]) > 3000


def test_a_fingerprint_comparison_that_finds_nothing_to_compare_fails(tmp_path, monkeypatch, capsys):
    """scripts/fingerprint.py --compare once read the goldens' file (cases under "cases") as empty and
    printed "identical": a comparison without the cases it was asked for is a failure."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("fingerprint_script", Path(__file__).parents[1] / "scripts" /
                                                  "fingerprint.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    monkeypatch.setattr(script, "CASES", {"cheap": lambda: {"episode": "abc"}})
    golden = tmp_path / "golden.json"
    golden.write_text(json.dumps({"cases": {"cheap": {"episode": "abc", "made_on": "x", "passed_on": ["x"]}}}))
    assert script.main(["--cases", "cheap", "--compare", str(golden)]) == 0
    golden.write_text(json.dumps({"cases": {"cheap": {"episode": "abd"}}}))
    assert script.main(["--cases", "cheap", "--compare", str(golden)]) == 1
    golden.write_text(json.dumps({"cases": {}}))
    assert script.main(["--cases", "cheap", "--compare", str(golden)]) == 1
    assert "nothing to compare" in capsys.readouterr().out


# ------------------------------------------------------------------------------------ goldens


def _same(case: str, got: dict, parts=("episode",)) -> None:
    want = GOLDEN["cases"][case]
    moved = [p for p in parts if got[p] != want[p]]
    assert not moved, (f"{case}: {', '.join(moved)} differ from the golden made on {want['made_on']} under "
                       f"{GOLDEN['numerics']} (passed on {'; '.join(want['passed_on'])}): some CPU dispatch is "
                       "not pinned on this machine, or the code changed what it computes (then make it again: "
                       "scripts/fingerprint.py --golden tests/golden/fingerprints.json --remake)")


def test_goldens_were_made_under_the_pins_this_package_sets():
    assert GOLDEN["numerics"] == N.PINNED and GOLDEN["warp_cpu_compiler_flags"] == N.WARP_PINNED_FLAGS


def test_the_tactile_frame_is_the_golden_one():
    _same("tactile_frame", F.tactile_frame(), ("pressure", "rigid", "geometric", "episode"))


def test_a_committed_policys_action_chunk_is_the_golden_one():
    _same("dp_inference", DP.dp_inference())


# The policy's action chunk keeps a golden in the default run.
@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
@pytest.mark.parametrize("case", ["dp_training", "dp_training_float32_products"])
def test_training_a_small_diffusion_policy_gives_the_golden_weights(case):
    got = DP.CASES[case]()
    _same(case, got, ("losses", "weights", "episode"))


@pytest.mark.parametrize("case", ["expert_soft", "expert_rigid"])
def test_an_expert_episode_is_the_golden_one(case):
    _same(case, F.CASES[case](), ("states", "rgb", "tactile", "episode"))


# Its two halves, the policy's action chunk and the rigid expert episode, keep goldens of their own
# in the default run.
@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
def test_a_committed_policys_first_id_episode_is_the_golden_one():
    _same("record", F.CASES["record"](), ("steps", "r_max", "termination", "episode"))


def test_a_records_file_holds_one_numerics_and_resuming_it_under_others_is_refused(tmp_path):
    from mani_skill_softvt.evaluation.records import seal
    from mani_skill_softvt.evaluation.run import RunConfig
    from mani_skill_softvt.evaluation.runner import evaluate

    run = RunConfig.resolve("expert", tasks=(3,), episodes_per_task=2)
    ep = run.episodes()[0]
    old = seal({**ep, **run.record_fields(), "termination": "success", "success": True, "dsr_success": True,
                "receipt": {"stack": {"cpu": "Intel(R) Xeon(R) Processor"}}})  # made before the pins
    path = tmp_path / "records.jsonl"
    path.write_text(json.dumps(old) + "\n")
    with pytest.raises(ValueError, match="made under numerics native.*SOFTVT_NUMERICS=native"):
        evaluate(run, path)
    # A file with nothing left to run is read as it is (its report rewritten), whatever it was made under.
    assert [r["seed"] for r in evaluate(RunConfig.resolve("expert", tasks=(3,)), path)] == [ep["seed"]]


@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
def test_a_campaign_command_run_on_its_own_runs_under_the_pins():
    """softvt-train and python -m softvt_campaign... import the campaign first: it imports the library
    before numpy or torch, so the pins hold there too."""
    import subprocess
    import sys

    code = ("import softvt_campaign.baselines.train\n"
            "from mani_skill_softvt.provenance.numerics import resolved\n"
            "r = resolved(); print(r['pinned'], r['loaded_before_pin'])")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SOFTVT_NUMERICS", "ATEN_", "OPENBLAS_", "NPY_",
                                                                      "MKL_", "ONEDNN_", "DNNL_", "OPENCV_", "LP_"))}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[0] == "True", out.stdout
