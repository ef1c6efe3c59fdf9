"""Reading a creative CLF file: malformed or unsupported files are refused with a ValueError naming the problem."""

import pytest
import torch

from torchgrade.io import read_clf

TABLE = " ".join(["0 0 0", "0 0 1", "0 1 0", "0 1 1", "1 0 0", "1 0 1", "1 1 0", "1 1 1"])


def clf(body: str) -> str:
    return f'<?xml version="1.0" encoding="UTF-8"?>\n<ProcessList id="t" compCLFversion="3">\n{body}\n</ProcessList>\n'


def lut3d(array: str = TABLE, dim: str = "2 2 2 3", attributes: str = 'inBitDepth="32f" outBitDepth="32f"') -> str:
    return f'<LUT3D {attributes}><Array dim="{dim}">{array}</Array></LUT3D>'


@pytest.mark.parametrize("text, message", [
    ("not xml <", "not a well-formed CLF"),
    ('<?xml version="1.0"?><Other/>', "root is ProcessList"),
    (clf(""), "one LUT3D"),
    (clf('<Matrix inBitDepth="32f" outBitDepth="32f"/>' + lut3d()), "apply other CLF files with OpenColorIO"),
    (clf(lut3d() + lut3d()), "one LUT3D"),
    (clf(lut3d(dim="2 2 3 3")), "dim must be 'S S S 3'"),
    (clf(lut3d(dim="1 1 1 3", array="0 0 0")), "size must lie in"),
    (clf(lut3d(array=TABLE + " 0")), "needs 24 numbers, got 25"),
    (clf(lut3d(array=TABLE.replace("1 1 1", "1 1 nan"))), "not finite"),
    (clf(lut3d(array=TABLE.replace("1 1 1", "1 1 1e39"))), "not finite"),
    (clf(lut3d(array=TABLE.replace("1 1 1", "1 1 x"))), "not a number"),
    (clf(lut3d(attributes='inBitDepth="32f" outBitDepth="7i"')), "outBitDepth must be one of"),
    (clf(lut3d(attributes='inBitDepth="99i" outBitDepth="32f"')), "LUT3D inBitDepth must be one of"),
    (clf(lut3d(attributes='interpolation="cubic"')), "trilinear or tetrahedral"),
    (clf('<Range inBitDepth="32f" outBitDepth="32f"><minInValue>0</minInValue></Range>' + lut3d()), "needs maxInValue"),
    (clf('<Range><minInValue>0</minInValue><maxInValue>1</maxInValue><minOutValue>0</minOutValue><maxOutValue>2</maxOutValue></Range>'
         + lut3d()), "onto \\[0, 1\\]"),
])
def test_a_malformed_clf_is_a_value_error_naming_the_problem(tmp_path, text, message):
    path = tmp_path / "look.clf"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        read_clf(path)


def test_a_range_before_the_table_is_its_domain_and_ten_bit_codes_are_scaled(tmp_path):
    path = tmp_path / "look.clf"
    codes = TABLE.replace("1", "1023")
    path.write_text(clf('<Range><minInValue>-1</minInValue><maxInValue>3</maxInValue><minOutValue>0</minOutValue>'
                        '<maxOutValue>1</maxOutValue></Range>' + lut3d(codes, attributes='inBitDepth="32f" outBitDepth="10i"')))
    lut = read_clf(path)
    assert lut.size == 2 and float(lut.domain_min.flatten()[0]) == -1.0 and float(lut.domain_max.flatten()[0]) == 3.0
    assert torch.allclose(lut(torch.full((1, 3, 1, 1), 1.0)), torch.full((1, 3, 1, 1), 0.5))  # (1 - -1) / 4 of the way
