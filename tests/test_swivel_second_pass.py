"""The swivel search's second pass leaves out only limbs that no hint can come of."""

import numpy as np

from ibik_pin.configuration import Configuration
from ibik_pin.tasks import ImageTask
from ibik_pin.tasks.silhouette_axis import SilhouetteAxisTask
from ibik_pin.tracking.swivel import SwivelSearch
from tests.conftest import random_human_configuration
from tests.test_swivel import _views

FREE = ["LElbow", "RElbow", "LKnee", "RKnee"]


def test_the_hints_are_those_of_every_limb_scored_twice(human, rng):
    """A search whose min_distance is 0 scores every limb's finer points; its hints farther than
    min_distance from their joints must be exactly the hints of the search that leaves limbs out."""
    hints_seen = 0
    for noise in (0.0, 0.03, 0.06, 0.1, 0.0, 0.03, 0.06, 0.1):
        seen_q = random_human_configuration(human, rng, spread=0.5)
        image_views, axis_views = _views(human, seen_q)
        image, axis = ImageTask(human, image_views), SilhouetteAxisTask(human, axis_views)
        terms = [(image, 1.0), (axis, 1.0)]
        # The solve's pose: the seen one (joints at their best swivel: limbs the second pass leaves
        # out), or the seen one with every joint moved (some hinted far).
        moved = np.r_[np.zeros(7), rng.normal(0.0, noise, human.model.nv - 6)]
        configuration = Configuration(human.model, seen_q + moved)
        for inside in (None, image.inside_silhouettes):
            cut = SwivelSearch(human, terms, inside_silhouettes=inside).hints(configuration, FREE)
            every = SwivelSearch(human, terms, inside_silhouettes=inside, min_distance=0.0).hints(configuration, FREE)
            joints = {name: configuration.frame_position(human.frame_id(name)) for name in every}
            far = {name: point for name, point in every.items() if np.linalg.norm(point - joints[name]) > 0.02}
            assert cut.keys() == far.keys()
            for name, point in far.items():
                np.testing.assert_array_equal(cut[name], point)
            hints_seen += len(far)
    assert hints_seen > 0  # the comparison is not between empty answers
