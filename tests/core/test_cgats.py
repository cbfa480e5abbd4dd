"""CGATS / Argyll .ti3 writer and reader: format rules, exact round trips, variants, errors."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from tests.tolerances import ATOL_ROUNDTRIP
from tunespec.core.datasets import load_colorchecker_sg
from tunespec.core.errors import InputError
from tunespec.core.io.cgats import (
    CgatsTable,
    _from_percent,
    _percent_text,
    format_cgats,
    parse_cgats,
    read_cgats,
    spectral_field_wavelength,
    ti3_field_name,
    ti3_table,
    write_cgats,
)
from tunespec.core.spectra import Grid, Spectra

CREATED = "2026-01-02T03:04:05+00:00"


@pytest.fixture(scope="module")
def sg() -> Spectra:
    return load_colorchecker_sg()


def _data_lines(text: str) -> list[str]:
    return text.split("BEGIN_DATA\n")[1].split("END_DATA")[0].strip().splitlines()


def test_ti3_layout_follows_argyll(sg: Spectra) -> None:
    rgb = np.random.default_rng(0).random((len(sg), 3))
    text = format_cgats(ti3_table(sg.names, reflectance=sg, rgb=rgb, created=CREATED))
    lines = text.splitlines()
    assert lines[0] == "CTI3"
    for kw in (
        'DEVICE_CLASS "INPUT"',
        'COLOR_REP "XYZ_RGB"',
        'SPECTRAL_BANDS "71"',
        'SPECTRAL_START_NM "380.0"',
        'SPECTRAL_END_NM "730.0"',
        f'CREATED "{CREATED}"',
    ):
        assert kw in lines
    # Non-standard keywords and fields are declared; standard ones are not.
    assert (
        lines.index('KEYWORD "DEVICE_CLASS"') == lines.index('DEVICE_CLASS "INPUT"') - 1
    )
    assert 'KEYWORD "SAMPLE_NAME"' in lines and 'KEYWORD "SPEC_380"' in lines
    assert 'KEYWORD "RGB_R"' not in lines and 'KEYWORD "DESCRIPTOR"' not in lines
    fields = lines[lines.index("BEGIN_DATA_FORMAT") + 1].split()
    assert fields[:5] == ["SAMPLE_ID", "SAMPLE_NAME", "RGB_R", "RGB_G", "RGB_B"]
    assert fields[5] == "SPEC_380" and fields[-1] == "SPEC_730" and len(fields) == 76
    assert "NUMBER_OF_FIELDS 76" in lines and "NUMBER_OF_SETS 140" in lines


def test_every_number_has_a_decimal_point(sg: Spectra) -> None:
    # Argyll types an all-integer column as integer and then rejects it.
    refl = sg.with_values(np.round(sg.values, 2))  # many 0.5 -> "50.0" percent
    refl = refl.with_values(np.where(refl.values > 0.9, 1.0, refl.values))
    t = ti3_table(
        refl.names,
        reflectance=refl,
        rgb=np.ones((len(refl), 3)),
        xyz=np.full((len(refl), 3), 100.0),
        lab=np.zeros((len(refl), 3)),
        created=CREATED,
    )
    for line in _data_lines(format_cgats(t)):
        numbers = line.split()[2:]
        assert len(numbers) == 3 + 3 + 3 + 71
        assert all("." in x for x in numbers), line
    assert _data_lines(format_cgats(t))[0].split()[2:5] == ["100.0"] * 3


def test_round_trip_is_exact(tmp_path: Path, sg: Spectra) -> None:
    rng = np.random.default_rng(1)
    rgb, xyz, lab = (
        rng.random((140, 3)),
        100 * rng.random((140, 3)),
        rng.random((140, 3)),
    )
    t = ti3_table(sg.names, reflectance=sg, rgb=rgb, xyz=xyz, lab=lab, created=CREATED)
    path = write_cgats(t, tmp_path / "a.ti3")
    back = read_cgats(path)
    spectra = back.spectra()
    assert spectra is not None
    np.testing.assert_array_equal(spectra.wavelength_nm, sg.wavelength_nm)
    np.testing.assert_allclose(spectra.values, sg.values, rtol=0, atol=ATOL_ROUNDTRIP)
    assert spectra.names == sg.names
    assert spectra.meta["spectral_scale"] == "100"
    for name, want in (("RGB_R", rgb[:, 0]), ("RGB_B", rgb[:, 2])):
        np.testing.assert_allclose(
            back.column(name, percent=True), want, rtol=0, atol=ATOL_ROUNDTRIP
        )
    np.testing.assert_array_equal(back.xyz, xyz)
    np.testing.assert_array_equal(back.lab, lab)
    assert back.keywords == t.keywords and back.fields == t.fields
    assert back.rows == t.rows and back.text_fields == t.text_fields
    assert format_cgats(back) == path.read_text()


def test_percent_conversion_is_exact_where_times_100_is_not() -> None:
    v = np.random.default_rng(2).random(20_000).tolist()
    exact = [_from_percent(_percent_text(x)) == x for x in v]
    naive = [float(repr(x * 100)) / 100 == x for x in v]
    assert all(exact)
    assert not all(naive)  # why the decimal point is moved instead
    assert _percent_text(0.07) == "7.0" and _percent_text(1e-9) == "0.0000001"
    assert _percent_text(-0.0) == "-0.0" and _percent_text(1e-30) == "1.0e-28"


def test_names_that_need_quotes_round_trip() -> None:
    names = ["A 1", 'say "hi"', "#3", "12", "2.5", "END_DATA", "ok"]
    wl = np.array([400.0, 500.0, 600.0])
    refl = Spectra(wl, np.full((7, 3), 0.25), tuple(names))
    t = ti3_table(names, reflectance=refl, created=CREATED)
    text = format_cgats(t)
    first = _data_lines(text)[0]
    assert first.startswith('"A 1" "A 1" ')
    assert '"say ""hi""" "say ""hi"""' in text
    back = parse_cgats(text)
    assert back.sample_names == tuple(names)
    assert back.text_column("SAMPLE_ID") == tuple(names)
    assert back.spectra().names == tuple(names)


def test_sub_nanometre_wavelengths_come_back_from_the_keywords() -> None:
    grid = Grid(380.0, 400.0, 2.5)
    s = Spectra(grid.wavelength_nm, np.linspace(0.1, 0.9, 9)[None, :], ("P",))
    t = ti3_table(["P"], reflectance=s, created=CREATED)
    assert t.fields[2:5] == ("SPEC_380", "SPEC_383", "SPEC_385")  # Argyll's rounding
    back = parse_cgats(format_cgats(t)).spectra()
    np.testing.assert_array_equal(back.wavelength_nm, grid.wavelength_nm)
    np.testing.assert_array_equal(back.values, s.values)


# A file as ArgyllCMS 2.3.1 spec2cie writes it: no KEYWORD lines, trailing blanks,
# integral values written without a decimal point.
ARGYLL_OUTPUT = (
    "\n".join(
        [
            "CTI3   ",
            "",
            'DESCRIPTOR "test"',
            'ORIGINATOR "me"',
            'DEVICE_CLASS "INPUT"',
            'COLOR_REP "XYZ_RGB"',
            'SPECTRAL_BANDS "3"',
            'SPECTRAL_START_NM "400.0"',
            'SPECTRAL_END_NM "500.0"',
            'CREATED "November 22, 2026"',
            "",
            "NUMBER_OF_FIELDS 10",
            "BEGIN_DATA_FORMAT",
            "SAMPLE_ID RGB_R RGB_G RGB_B SPEC_400 SPEC_450 SPEC_500 LAB_L LAB_A LAB_B ",
            "END_DATA_FORMAT",
            "",
            "NUMBER_OF_SETS 2",
            "BEGIN_DATA",
            "A1 10 20 30 50 50 50 76.141 -0.283286 -0.301498 ",
            "A2 10.5 20 30 60 50 50 76.0705 -0.0251469 0.0514406 ",
            "END_DATA",
        ]
    )
    + "\n"
)


def test_reads_argyll_output_without_keyword_lines() -> None:
    t = parse_cgats(ARGYLL_OUTPUT)
    assert t.file_id == "CTI3" and t.keywords["DEVICE_CLASS"] == "INPUT"
    assert t.keywords["CREATED"] == "November 22, 2026"
    assert t.sample_names == ("A1", "A2")
    np.testing.assert_array_equal(t.rgb, [[10, 20, 30], [10.5, 20, 30]])
    np.testing.assert_array_equal(t.lab[:, 0], [76.141, 76.0705])
    s = t.spectra()
    np.testing.assert_array_equal(s.wavelength_nm, [400.0, 450.0, 500.0])
    np.testing.assert_array_equal(s.values, [[0.5, 0.5, 0.5], [0.6, 0.5, 0.5]])


@pytest.mark.parametrize(
    ("fields", "scale"),
    [
        ("SPECTRAL_NM_400 SPECTRAL_NM_450 SPECTRAL_NM_500", 1.0),
        ("SPECTRAL_NM400 SPECTRAL_NM450 SPECTRAL_NM500", 1.0),
        ("nm400 nm450 nm500", 1.0),
        ("R_400 R_450 R_500", 1.0),
        ("nm400 nm450 nm500", 100.0),
    ],
)
def test_spectral_field_variants_and_scale(fields: str, scale: float) -> None:
    # An X-Rite style CGATS.17 file: tabs, numeric SAMPLE_ID, SAMPLE_NAME, comments.
    v = np.array([[0.05, 0.5, 0.95], [0.012, 0.0345, 0.9]]) * scale
    rows = "\n".join(
        f'{i + 1}\t"{n}"\t' + "\t".join(repr(float(x)) for x in row)
        for i, (n, row) in enumerate(zip(("W 1", "K"), v, strict=True))
    )
    text = (
        'CGATS.17\n# exported by some instrument\nORIGINATOR\t"x"\n'
        "NUMBER_OF_FIELDS 5\nBEGIN_DATA_FORMAT\n"
        f"SAMPLE_ID\tSAMPLE_NAME\t{fields.replace(' ', chr(9))}\nEND_DATA_FORMAT\n"
        f"NUMBER_OF_SETS 2\nBEGIN_DATA\n{rows}\nEND_DATA\n"
    )
    t = parse_cgats(text)
    s = t.spectra()
    assert s.names == ("W 1", "K")
    np.testing.assert_array_equal(s.wavelength_nm, [400.0, 450.0, 500.0])
    np.testing.assert_allclose(s.values, v / scale, rtol=1e-15, atol=0)
    assert s.meta["spectral_scale"] == f"{scale:g}"
    assert t.text_column("SAMPLE_ID") == ("1", "2")


def test_spectral_field_names() -> None:
    assert spectral_field_wavelength("SPEC_380") == 380.0
    assert spectral_field_wavelength("spectral_nm_1000") == 1000.0
    assert spectral_field_wavelength("NM_382.5") == 382.5
    for not_spectral in ("RGB_R", "SPEC_38", "SAMPLE_ID", "R_G", "LAB_L"):
        assert spectral_field_wavelength(not_spectral) is None
    assert ti3_field_name(379.5) == "SPEC_380" and ti3_field_name(380.49) == "SPEC_380"


def test_multi_table_file_reads_the_first_table() -> None:
    second = "\nCAL\n\nNUMBER_OF_FIELDS 1\nBEGIN_DATA_FORMAT\nRGB_I\nEND_DATA_FORMAT\n"
    t = parse_cgats(
        ARGYLL_OUTPUT + second + "NUMBER_OF_SETS 1\nBEGIN_DATA\n0.5\nEND_DATA\n"
    )
    assert len(t) == 2 and t.fields[0] == "SAMPLE_ID"


GOOD = ARGYLL_OUTPUT.splitlines()


def _with(line_no: int, new: str | None) -> str:
    lines = list(GOOD)
    if new is None:
        del lines[line_no - 1]
    else:
        lines[line_no - 1] = new
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        (_with(1, "NUMBER_OF_FIELDS 3"), 1, "expected a file identifier"),
        (_with(3, 'DESCRIPTOR "test'), 3, "unterminated quoted string"),
        (_with(19, "A1 10 20 30 50 50 50 76.141 -0.28"), 19, "9 values, expected 10"),
        (_with(19, "A1 ten 20 30 50 50 50 1 2 3"), 19, "RGB_R: not a number: 'ten'"),
        (_with(19, "A1 10 20 30 5,0 50 50 1 2 3"), 19, "SPEC_400: not a number"),
        (_with(17, "NUMBER_OF_SETS 3"), 17, "NUMBER_OF_SETS is 3 but 2 sets follow"),
        (_with(17, "NUMBER_OF_SETS many"), 17, "NUMBER_OF_SETS needs one"),
        (_with(14, "SAMPLE_ID RGB_R RGB_R RGB_B"), 13, "duplicate field(s) RGB_R"),
        (_with(14, 'SAMPLE_ID "RGB R" RGB_G'), 13, "bad CGATS field name 'RGB R'"),
        (
            ARGYLL_OUTPUT.replace(
                "A1 10 20 30 50 50 50 76.141 -0.283286 -0.301498 \n", ""
            )
            .replace("A2 10.5 20 30 60 50 50 76.0705 -0.0251469 0.0514406 \n", "")
            .replace("NUMBER_OF_SETS 2", "NUMBER_OF_SETS 0"),
            18,
            "no data sets between BEGIN_DATA and END_DATA",
        ),
        (_with(21, None), 20, "END_DATA missing"),  # the last line
        (_with(15, None), 16, "NUMBER_OF_SETS inside BEGIN_DATA_FORMAT"),
        (_with(21, "END_DATA junk"), 21, "text after END_DATA"),
    ],
    ids=lambda v: v if isinstance(v, str) and len(v) < 45 else None,
)
def test_malformed_files_name_the_line(
    tmp_path: Path, text: str, line: int, message: str
) -> None:
    path = tmp_path / "bad.ti3"
    path.write_text(text)
    with pytest.raises(InputError, match=re.escape(message)) as info:
        read_cgats(path)
    assert info.value.line == line
    assert str(info.value).startswith(f"{path}:{line}: ")


def test_number_of_fields_is_not_checked_against_the_format_list() -> None:
    # As in ArgyllCMS, whose own ref/ColorChecker.ti2 and ref/FograStrip3.ti1 say
    # NUMBER_OF_FIELDS 9 and list 8 fields; the format list and the data decide.
    for n in ("9", "11"):
        t = parse_cgats(
            ARGYLL_OUTPUT.replace("NUMBER_OF_FIELDS 10", f"NUMBER_OF_FIELDS {n}")
        )
        assert len(t.fields) == 10 and t.sample_names == ("A1", "A2")
    with pytest.raises(InputError, match="NUMBER_OF_FIELDS needs one non-negative"):
        parse_cgats(ARGYLL_OUTPUT.replace("NUMBER_OF_FIELDS 10", "NUMBER_OF_FIELDS x"))


def test_format_on_one_line() -> None:
    text = ARGYLL_OUTPUT.replace(
        "BEGIN_DATA_FORMAT\nSAMPLE_ID", "BEGIN_DATA_FORMAT SAMPLE_ID"
    ).replace("LAB_B \nEND_DATA_FORMAT", "LAB_B END_DATA_FORMAT")
    t = parse_cgats(text)
    assert t.fields == parse_cgats(ARGYLL_OUTPUT).fields and len(t) == 2


def test_file_level_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="file not found"):
        read_cgats(tmp_path / "missing.ti3")
    (tmp_path / "empty.ti3").write_text("\n# nothing\n")
    with pytest.raises(InputError, match="empty file"):
        read_cgats(tmp_path / "empty.ti3")
    no_data = ARGYLL_OUTPUT.replace(
        "A1 10 20 30 50 50 50 76.141 -0.283286 -0.301498 \n", ""
    )
    no_data = no_data.replace(
        "A2 10.5 20 30 60 50 50 76.0705 -0.0251469 0.0514406 \n", ""
    )
    with pytest.raises(InputError, match="no data sets"):
        parse_cgats(no_data.replace("NUMBER_OF_SETS 2", "NUMBER_OF_SETS 0"))
    # Latin-1 text from Windows instrument software reads.
    (tmp_path / "latin1.txt").write_bytes(
        ARGYLL_OUTPUT.replace('"me"', '"Müller"').encode("latin-1")
    )
    assert read_cgats(tmp_path / "latin1.txt").keywords["ORIGINATOR"] == "Müller"


def test_ti3_table_rejects_bad_input() -> None:
    wl = np.array([400.0, 410.0])
    s = Spectra(wl, np.array([[0.1, 0.2], [0.3, 0.4]]), ("a", "b"))
    with pytest.raises(InputError, match="duplicate patch names: a"):
        ti3_table(["a", "a"])
    with pytest.raises(InputError, match=r"rgb has shape \(1, 3\), expected \(2, 3\)"):
        ti3_table(["a", "b"], rgb=[[1, 2, 3]])
    with pytest.raises(InputError, match="xyz has non-finite values"):
        ti3_table(["a", "b"], xyz=[[1, 2, np.nan], [1, 2, 3]])
    with pytest.raises(InputError, match="not found: c"):
        ti3_table(["a", "c"], reflectance=s)
    fine = Spectra(np.array([400.0, 400.4]), np.array([[0.1, 0.2]]), ("a",))
    with pytest.raises(InputError, match="below 1 nm"):
        ti3_table(["a"], reflectance=fine)
    uneven = Spectra(np.array([400.0, 410.0, 430.0]), np.ones((1, 3)), ("a",))
    with pytest.raises(InputError, match="equidistant"):
        ti3_table(["a"], reflectance=uneven)
    with pytest.raises(ValueError, match="non-finite"):
        CgatsTable("CTI3", {}, ("X",), ((float("inf"),),))
    with pytest.raises(InputError, match="bad CGATS keyword"):
        CgatsTable("CTI3", {"NUMBER_OF_SETS": "1"}, ("X",), (("1.0",),))


def test_extra_fields_and_keywords() -> None:
    t = ti3_table(
        ["a", "b"],
        keywords={"TUNESPEC_SESSION": "s 1"},
        extra_fields={"EXPOSURE_S": [0.25, 0.5], "NOTE": ["x", "12"]},
        created=CREATED,
    )
    back = parse_cgats(format_cgats(t))
    assert back.keywords["TUNESPEC_SESSION"] == "s 1"
    np.testing.assert_array_equal(back.column("EXPOSURE_S"), [0.25, 0.5])
    assert back.text_column("NOTE") == ("x", "12")  # "12" stays text (quoted)
    assert "COLOR_REP" not in back.keywords  # no device values, no COLOR_REP
    with pytest.raises(InputError, match="holds text"):
        back.column("NOTE")
    assert back.spectra() is None
