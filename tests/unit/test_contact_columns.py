"""The contact output is declared once (pdem.io.joints.OutputColumn): the datasets of
``contacts/`` and ``subcontacts/`` and the ParaView sidecar's point attributes come from the
same table, so a column shown in ParaView is one declaration with a ``view``."""

from __future__ import annotations

import numpy as np

from pdem.io import joints, xdmf


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
