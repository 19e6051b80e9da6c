"""bench/gpu.sh and bench/bench_gpu.py where no GPU is: one clear line, exit 2, nothing
written; and the device choice that picks the GPU among EGL devices."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))
import bench_gpu  # noqa: E402


def test_gpu_script_refuses_without_a_gpu(tmp_path):
    out = tmp_path / "gpu"
    env = {"PATH": "/usr/bin:/bin"}  # no nvidia-smi on this machine's system path
    assert subprocess.run(["which", "nvidia-smi"], env=env, capture_output=True).returncode
    done = subprocess.run(["bash", str(ROOT / "bench" / "gpu.sh"), str(out)], env=env,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "no NVIDIA GPU found" in lines[0] and len(lines[0]) < 300
    assert done.stdout == "" and not out.exists()


def test_bench_refuses_software_egl(tmp_path):
    """This machine's EGL is Mesa's llvmpipe: named, and refused as no GPU."""
    names = bench_gpu.egl_devices()
    assert names and "llvmpipe" in names[0]
    done = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_gpu.py"), "--out",
                           str(tmp_path / "gpu")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "no EGL device is a GPU" in done.stderr
    assert not (tmp_path / "gpu").exists()


def test_gpu_index_skips_software_devices():
    names = ["llvmpipe (LLVM 15.0.6, 256 bits) (Mesa/X.org, GL 450)",
             "NVIDIA H100 80GB HBM3/PCIe/SSE2 (NVIDIA Corporation, GL 460)"]
    assert bench_gpu.gpu_index(names) == 1
    with pytest.raises(bench_gpu.NoGPU, match="no EGL device is a GPU"):
        bench_gpu.gpu_index(names[:1])


def test_compare_reports_label_and_depth_agreement(tmp_path):
    depth = np.full((4, 6), 10.0, np.float32)
    labels = np.zeros((4, 6), np.uint8)
    np.savez(tmp_path / "a.npz", component_000=labels, damage_000=labels, depth_000=depth)
    moved = labels.copy()
    moved[0, 0] = 3
    np.savez(tmp_path / "b.npz", component_000=moved, damage_000=labels,
             depth_000=depth * (1 + 2e-6))
    result = bench_gpu.compare(tmp_path / "a.npz", tmp_path / "b.npz")
    assert result["label_share_equal"] == {"component": 23 / 24, "damage": 1.0}
    assert not result["labels_identical"] and not result["depth_within_rtol"]
    assert result["depth_max_rel"] == pytest.approx(2e-6, rel=0.05)
    same = bench_gpu.compare(tmp_path / "a.npz", tmp_path / "a.npz")
    assert same["labels_identical"] and same["depth_within_rtol"]


def test_compare_tells_edge_pixels_from_others_and_refuses_other_views(tmp_path):
    """A label that differs beside another label is a rasterizer's tie; one inside a region
    is a wrong label. A reference of other views is refused, not compared."""
    labels = np.zeros((6, 6), np.uint8)
    labels[:, 3:] = 2
    depth = np.full((6, 6), 5.0, np.float32)
    np.savez(tmp_path / "cpu.npz", component_001=labels, damage_001=labels, depth_001=depth)
    gpu = labels.copy()
    gpu[2, 3] = 0  # beside the edge
    gpu[4, 0] = 7  # inside the region
    np.savez(tmp_path / "gpu.npz", component_001=gpu, damage_001=labels, depth_001=depth)
    result = bench_gpu.compare(tmp_path / "gpu.npz", tmp_path / "cpu.npz")
    assert result["labels_differ"] == {"component": 2, "damage": 0}
    assert result["labels_differ_off_edges"] == {"component": 1, "damage": 0}
    assert not result["labels_identical_off_edges"]
    np.savez(tmp_path / "other.npz", component_002=labels, damage_002=labels, depth_002=depth)
    with pytest.raises(ValueError, match="same --views"):
        bench_gpu.compare(tmp_path / "gpu.npz", tmp_path / "other.npz")


def test_a_dropped_thin_region_or_a_third_label_on_an_edge_is_no_tie():
    cpu = np.zeros((6, 8), np.uint8)
    cpu[3, :] = 5  # a crack one pixel wide
    assert not bench_gpu.edge_ties(np.zeros_like(cpu), cpu)[3].any()  # dropped whole
    moved = np.roll(cpu, 1, axis=0)  # the same crack a pixel lower: ties all along
    assert bench_gpu.edge_ties(moved, cpu)[moved != cpu].all()
    third = cpu.copy()
    third[3, 2] = 9
    assert not bench_gpu.edge_ties(third, cpu)[3, 2]


def test_compare_reports_crack_pixels_and_widths(tmp_path):
    """A crack drawn a pixel lower is a tie at its edge; a crack pixel only one render drew,
    away from any crack, is not; widths are compared where both drew the crack."""
    labels = np.zeros((8, 8), np.uint8)
    depth = np.full((8, 8), 3.0, np.float32)
    cpu = np.zeros((8, 8), np.float32)
    cpu[4, 1:7] = 0.5
    gpu = np.roll(cpu, 1, axis=0)
    gpu[4, 1:7] = 0.51  # the crack two rows wide here, 2 % wider
    gpu[0, 0] = 0.2  # far from the CPU's crack
    for name, width in (("gpu", gpu), ("cpu", cpu)):
        np.savez(tmp_path / f"{name}.npz", component_003=labels, damage_003=labels,
                 depth_003=depth, crack_width_003=width)
    crack = bench_gpu.compare(tmp_path / "gpu.npz", tmp_path / "cpu.npz")["crack"]
    assert (crack["pixels_gpu"], crack["pixels_cpu"]) == (13, 6)
    assert (crack["pixels_differ"], crack["pixels_differ_off_edges"]) == (7, 1)
    assert (crack["pixels_gpu_only"], crack["pixels_cpu_only"]) == (7, 0)
    assert crack["width_median_rel"] == pytest.approx(0.02, rel=1e-4)
    same = bench_gpu.compare(tmp_path / "gpu.npz", tmp_path / "gpu.npz")["crack"]
    assert same["pixels_differ"] == 0 and same["width_max_rel"] == 0


def test_a_missing_reference_is_one_line_before_any_render(tmp_path):
    done = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_gpu.py"), "--out",
                           str(tmp_path / "gpu"), "--cpu-reference", str(tmp_path / "ref.npz")],
                          capture_output=True, text=True, timeout=60)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and "--cpu-only" in lines[0]
    assert "cpu_paper.npz" in lines[0] and not (tmp_path / "gpu").exists()


def test_a_reference_of_other_views_is_one_line_before_any_render(tmp_path):
    ref = tmp_path / "ref"
    ref.mkdir()
    np.savez(ref / "cpu_paper.npz", component_000=np.zeros((2, 2), np.uint8))
    (ref / "cpu_paper.json").write_text('{"views": 3}')
    done = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_gpu.py"), "--out",
                           str(tmp_path / "gpu"), "--presets", "paper", "--views", "4",
                           "--cpu-reference", str(ref)],
                          capture_output=True, text=True, timeout=60)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and "3 views, not --views 4's" in lines[0]
    assert not (tmp_path / "gpu").exists()


def test_an_unknown_preset_is_one_line_before_any_render(tmp_path):
    done = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_gpu.py"), "--out",
                           str(tmp_path / "gpu"), "--presets", "paper", "nopreset"],
                          capture_output=True, text=True, timeout=60)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and "nopreset" in lines[0]
    assert not (tmp_path / "gpu").exists()


def test_gpu_script_passes_options_to_the_bench_and_skips_the_install(tmp_path):
    """GLSYNTH_PYTHON, as on a machine that cannot install: no install, and OUT and the
    options reach bench_gpu.py (a stub that prints its arguments; nvidia-smi a stub too)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "nvidia-smi").write_text("#!/bin/sh\necho 'GPU 0: Stub GPU (UUID: GPU-0)'\n")
    (bin_dir / "stub-python").write_text("#!/bin/sh\necho \"args: $*\"\n")
    for name in ("nvidia-smi", "stub-python"):
        (bin_dir / name).chmod(0o755)
    out = tmp_path / "gpu"
    done = subprocess.run(["bash", str(ROOT / "bench" / "gpu.sh"), str(out), "--views", "4"],
                          env={"PATH": f"{bin_dir}:/usr/bin:/bin", "GLSYNTH_PYTHON": "stub-python"},
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert f"args: bench/bench_gpu.py --out {out} --views 4" in done.stdout
    assert "install" not in (out / "gpu.log").read_text()
