"""The shipped weights on a freshly generated held-out set, batches, bad segments."""

from __future__ import annotations

import numpy as np
import pytest

from hollowtree.classes import ClassId
from hollowtree.errors import ConfigError
from hollowtree.hollownet.dataset import DatasetParams, generate_samples
from hollowtree.hollownet.model import OUTPUT_CLASSES
from hollowtree.hollownet.predict import Classifier
from hollowtree.hollownet.train import confusion_matrix, format_confusion

#: Never used for training: the shipped weights saw seed 0, splits "train" and "test".
HELDOUT_SEED = 20_261_122


@pytest.fixture(scope="module")
def heldout():
    return generate_samples(DatasetParams(seed=HELDOUT_SEED, split="heldout", n_per_class=20, variants=2),
                            keep_points=True)


def test_heldout_accuracy_of_the_shipped_weights(heldout):
    clf = Classifier.get()
    pred = clf.predict(heldout["points"])
    assert pred.valid.all()
    index = {int(c): i for i, c in enumerate(OUTPUT_CLASSES)}
    cm = confusion_matrix([index[int(c)] for c in heldout["labels"]], [index[int(c)] for c in pred.class_id],
                          len(OUTPUT_CLASSES))
    acc = np.trace(cm) / cm.sum()
    print(f"\nheld-out accuracy {100 * acc:.2f} %\n" + format_confusion(cm, [c.label for c in OUTPUT_CLASSES]))
    assert cm.sum() == 20 * len(OUTPUT_CLASSES)
    assert acc >= 0.95
    # scores are the probabilities of the predicted classes
    np.testing.assert_allclose(pred.probabilities.sum(axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(pred.score, pred.probabilities.max(axis=1))
    # the stored grids of the same samples give the same answer as the points
    probs = clf.predict_grids(heldout["grids"])
    np.testing.assert_allclose(probs, pred.probabilities, atol=1e-5)


def test_batch_size_does_not_change_the_answer(heldout):
    pts = heldout["points"][::7]
    a = Classifier.get().predict(pts)
    b = Classifier(batch_size=3).predict(pts)
    np.testing.assert_array_equal(a.class_id, b.class_id)
    np.testing.assert_allclose(a.probabilities, b.probabilities, atol=1e-5)


def test_bad_segments_are_other_with_score_zero():
    clf = Classifier.get()
    rng = np.random.default_rng(0)
    ok = rng.normal(size=(500, 3)) * [1, 1, 4]
    nan = ok.copy()
    nan[3, 2] = np.nan
    segs = [np.zeros((0, 3)), np.array([[1.0, 2.0, 3.0]]), np.full((50, 3), 4.0), nan, ok, np.ones((20, 2))]
    class_ids, scores, probs = clf.predict(segs)
    bad = [0, 1, 2, 3, 5]
    assert (class_ids[bad] == ClassId.OTHER).all()
    assert (scores[bad] == 0).all()
    assert (probs[bad] == 0).all()
    assert scores[4] > 0
    assert probs[4].sum() == pytest.approx(1.0, abs=1e-5)
    assert clf.predict([]).class_id.shape == (0,)


def test_one_classifier_per_process():
    assert Classifier.get() is Classifier.get()
    with pytest.raises(ConfigError, match="precision"):
        Classifier(precision="int4")
