"""benchmarks/profile_render.py: the attribution of perf samples to inlined Warp functions
(pure functions, on synthetic objdump / addr2line output; the profile itself needs perf)."""
from __future__ import annotations

import pytest

from benchmarks import profile_render as PR

pytestmark = pytest.mark.lab  # tests lab code only (the `lab` marker of pyproject.toml)

DISASSEMBLY = """
0000000000000000 <kernel>:
       0:\tpush   %rbp
       1:\tmov    %rsp,%rbp
       4:\tvmovss (%rax),%xmm0
       8:\tvdivss %xmm1,%xmm0,%xmm0
       c:\tret
       d:\tnop
      10:\tcall   *%r13
"""

ADDR2LINE = """0x0000000000000004
void kernel_forward<true>(wp::launch_bounds_t<1>, unsigned long, args*)
/x/builtin.h:986
warp_sample_0
/x/k.cpp:10
_draw_0
/x/k.cpp:20
sample_f_0
/x/k.cpp:30
_sample_f_chain__locals__bsdf_sample_f_0
/x/k.cpp:40
make_kernels__locals__radiance_sample_0
/x/k.cpp:50
0x0000000000000008
void kernel_forward<true>(wp::launch_bounds_t<1>, unsigned long, args*)
/x/array.h:417
_split_0
/x/k.cpp:60
_sample_patch_uv_0
/x/k.cpp:70
env_sample_uv_0
/x/k.cpp:80
make_kernels__locals__radiance_sample_0
/x/k.cpp:50
0x0000000000000010
sample_2d_0(int, unsigned int, int, int, int)
/x/k.cpp:90
0x000000000000000c
void kernel_forward<true>(wp::launch_bounds_t<1>, unsigned long, args*)
/x/k.cpp:99
make_kernels__locals__radiance_sample_0
/x/k.cpp:51
"""


def test_instruction_starts_reads_objdump_offsets():
    assert PR.instruction_starts(DISASSEMBLY) == [0x0, 0x1, 0x4, 0x8, 0xC, 0xD, 0x10]


def test_load_base_is_where_every_sample_is_an_instruction_start():
    starts = PR.instruction_starts(DISASSEMBLY)
    base = 0x7F0000001000
    addresses = [base + o for o in (0x4, 0x8, 0x8, 0xC, 0x10, 0x1)]
    found, share = PR.find_load_base(addresses, starts)
    assert found == base and share == 1.0
    with pytest.raises(PR.ProfileError):
        PR.find_load_base([], starts)


def test_addr2line_chains_drop_the_enclosing_symbol_but_keep_outlined_functions():
    chains = PR.parse_addr2line(ADDR2LINE)
    assert chains[0x4][:2] == ["warp_sample_0", "_draw_0"]
    assert chains[0x4][-1] == "make_kernels__locals__radiance_sample_0"
    assert chains[0x10] == ["sample_2d_0"]          # not inlined: its own symbol
    assert chains[0xC] == ["make_kernels__locals__radiance_sample_0"]


def test_attribution_inclusive_exclusive_and_components():
    chains = PR.parse_addr2line(ADDR2LINE)
    inc, exc, comp = PR.attribute({0x4: 5, 0x8: 3, 0x10: 2, 0xC: 1}, chains)
    assert inc["make_kernels__locals__radiance_sample_0"] == 9
    assert inc["sample_f_0"] == 5 and inc["env_sample_uv_0"] == 3
    assert exc["warp_sample_0"] == 5 and exc["_split_0"] == 3 and exc["sample_2d_0"] == 2
    assert comp["BSDF sampling (sample + f at the sample)"] == 5
    assert comp["environment sampling"] == 3
    assert comp["sample generation (CMJ)"] == 2
    assert comp["other (integrator, frames, MIS)"] == 1
    assert sum(comp.values()) == 11


def test_report_shares_are_of_the_render_samples():
    res = {"material": "m", "envmap": "e", "spp": 4, "resolution": 16, "samples": 100, "kernel_samples": 30,
               "libm_samples": 10, "aligned_share": 1.0, "libm": {"__atanf": 10},
               "inclusive": {"a": 30}, "exclusive": {"a": 30}, "components": {"environment sampling": 20}}
    text = PR.report(res)
    assert " 50.0 %  environment sampling" in text and " 25.0 %  __atanf" in text


def test_missing_tool_is_one_line_exit_2(monkeypatch, capsys):
    monkeypatch.setattr(PR.shutil, "which", lambda name: None)
    assert PR.main(["--spp", "4"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "perf not found" in err[0]


def test_missing_fit_is_one_line_exit_2(monkeypatch, capsys, tmp_path):
    monkeypatch.setattr(PR.shutil, "which", lambda name: "/usr/bin/" + name)
    assert PR.main(["--fit", str(tmp_path / "no_such_fit.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--fit" in err[0] and "no_such_fit.json" in err[0]


CPP = """// header
    // a = mats.rgl_f[i]  <L 87>
    var_1 = wp::address(var_2, var_i);
    var_4 = wp::load(var_1);
    // return a + w1 * (b - a)  <L 90>
    var_11 = wp::sub(var_12, var_3);
""".splitlines()


def test_innermost_cpp_line_skips_headers_and_unknown_lines():
    text = ("0x0000000000000004\nf\n/x/array.h:444\ng\n/x/k.cpp:?\nh\n/x/k.cpp:3\nk\n/x/k.cpp:99\n"
            "0x0000000000000008\nf\n/x/k.cpp:6\n0x000000000000000c\nf\n/x/builtin.h:1\n")
    assert PR.innermost_cpp_lines(text) == {4: 3, 8: 6}


def test_samples_are_named_by_the_warp_statement_above_their_line():
    assert PR.warp_statement(CPP, 3) == "a = mats.rgl_f[i] <L 87>"
    assert PR.warp_statement(CPP, 4) == "a = mats.rgl_f[i] <L 87>"
    assert PR.warp_statement(CPP, 6) == "return a + w1 * (b - a) <L 90>"
    assert PR.warp_statement(CPP, 1) == "?"
    by = PR.attribute_lines({4: 5, 8: 2, 12: 1}, {4: 3, 8: 6}, CPP)
    assert by == {"a = mats.rgl_f[i] <L 87>": 5, "return a + w1 * (b - a) <L 90>": 2, "?": 1}
    res = {"material": "m", "envmap": "e", "resolution": 8, "spp": 1, "samples": 10, "kernel_samples": 8,
           "aligned_share": 1.0, "libm_samples": 0, "libm": {}, "inclusive": {}, "exclusive": {},
           "components": {}, "lines": dict(by.most_common())}
    assert "62.5 %  a = mats.rgl_f[i] <L 87>" in PR.report(res)
