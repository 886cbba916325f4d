"""The contact output is declared once (pdem.io.joints.OutputColumn): the datasets of
``contacts/`` and ``subcontacts/`` and the ParaView sidecar's point attributes come from the
same table, so a column shown in ParaView is one declaration with a ``view``."""

from __future__ import annotations

import numpy as np

from pdem.io import joints, xdmf
from pdem.model import fields


def test_the_sidecar_shows_the_declared_columns_in_view_order():
    for series, attrs, viewed in ((joints.CONTACT_SERIES, xdmf._CONTACT_ATTRS,
                                   xdmf.CONTACT_VIEWED),
                                  (joints.SUB_SERIES, xdmf._SUB_ATTRS, xdmf.SUB_VIEWED)):
        shown = [c for c in series if c.view is not None]
        assert sorted(c.view for c in shown) == list(range(len(shown)))  # no gap, no twice
        by_name = {c.name: c for c in series}
        assert [a[0] for a in attrs] == [c.name for c in sorted(shown, key=lambda c: c.view)]
        for name, components, number, precision in attrs:
            c = by_name[name]
            assert components == int(np.prod(c.shape))
            assert np.dtype(c.dtype).itemsize == precision
            assert (number == "Float") == np.issubdtype(c.dtype, np.floating)
        assert viewed == ("point", *(a[0] for a in attrs))  # the views the writer makes


def test_a_new_viewed_column_reaches_the_sidecar():
    extra = joints.OutputColumn("dilation", (), np.float32, "m", "test column", view=3)
    attrs = joints.viewer_attributes((*joints.SUB_SERIES[:-1], extra,
                                      joints.SUB_SERIES[-1]._replace(view=2)))
    assert attrs == (("normal_force", 1, "Float", 8), ("shear_force", 3, "Float", 8),
                     ("state", 1, "UChar", 1), ("dilation", 1, "Float", 4))


def test_every_reduced_value_is_a_declared_column():
    crows = np.zeros((1, joints.C_WIDTH))
    joints.col(crows, joints.C_AT, "n_sub")[:] = 1
    srows = np.zeros((1, joints.S_WIDTH))
    contacts, subs = joints.reduce_contacts(crows, srows)
    assert set(contacts) == {c.name for c in joints.CONTACT_SERIES}
    assert set(subs) == {c.name for c in joints.SUB_SERIES}


def test_the_stored_columns_are_declared_fields():
    """A column written as stored names its contact (or sub-contact) field; each is passed by
    the ranks (``CONTACT_COLS``/``SUB_COLS``) with the field's width, so a stored field shown
    in ParaView is its declaration (pdem.model.fields) and one column here."""
    for series, declared, passed in ((joints.CONTACT_SERIES, fields.CONTACT, joints.CONTACT_COLS),
                                     (joints.SUB_SERIES, fields.SUB, joints.SUB_COLS)):
        by_name = {f.name: f for f in declared}
        widths = dict(passed)
        for c in series:
            if c.field is None:
                continue
            assert c.field in by_name, f"{c.name}: {c.field} is not a declared field"
            assert by_name[c.field].shape == c.shape
            assert widths[c.name] == by_name[c.field].width
