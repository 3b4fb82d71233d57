"""Class and mobility of every track, with the leg detector the person life cycle too (tracker.Tracker's
docstring has the rules). References: tests/reference_tracking.ReferenceTracker._classify and classify_tracks.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from ..logs.vocabulary import (
    CLASS_CIRCLE_OBJECT,
    CLASS_PERSON,
    CLASS_RECTANGULAR_OBJECT,
    CLASS_UNKNOWN,
    MOBILITY_DYNAMIC,
)
from ._scan_measurements import K_BLOB, K_CIRCLE, K_LEG, K_PERSON, K_RECT
from .state import (
    BORN,
    CLS,
    CONFIRMED,
    FIRST_X,
    FIRST_Y,
    FREE,
    HIT,
    IS_PERSON,
    LEAD_LEFT,
    LEAD_RIGHT,
    LEG_SCORE,
    MOBILITY,
    MOVING_TIME,
    ON_BG,
    P_D_MAX,
    P_MOVING_DISTANCE,
    P_MOVING_SPEED,
    P_MOVING_TIME,
    P_PERSON_EVIDENCE,
    P_PERSON_EVIDENCE_UNFREE,
    P_PERSON_MAINTAIN,
    P_PERSON_PAIRS,
    P_PERSON_VOTES,
    P_STILL_TIME,
    P_UNDEFINED_WINDOW,
    SIZE,
    STILL_TIME,
    VOTES,
    VX,
    VY,
    X,
    Y,
)

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


@njit(cache=True)
def classify(tab, n, dt, stamp, learned, prm):
    """Class and mobility of every track (references: tests/reference_tracking's ReferenceTracker._classify
    and classify_tracks). With the leg detector, the person life cycle: a confirmed track becomes a person once
    its evidence reaches person_evidence (person_evidence_unfree while none of its legs was seen in free space)
    with person_pairs sightings of two legs, and stays one until its evidence
    falls below person_maintain; the rest are classified by the shape of their hits. Mobility apart."""
    for k in range(n):
        speed = np.hypot(tab[k, VX], tab[k, VY])
        if tab[k, HIT] != 0 and tab[k, ON_BG] == 0 and speed > prm[P_MOVING_SPEED]:
            tab[k, MOVING_TIME] = tab[k, MOVING_TIME] + dt
        else:
            tab[k, MOVING_TIME] = 0.0
        if speed > prm[P_MOVING_SPEED]:
            tab[k, STILL_TIME] = 0.0
        else:
            tab[k, STILL_TIME] = tab[k, STILL_TIME] + dt
        if learned and tab[k, MOBILITY] == MOBILITY_DYNAMIC and tab[k, STILL_TIME] >= prm[P_STILL_TIME]:
            # it stopped: static again (the paper's rule keeps it dynamic), and it must move moving_distance anew
            tab[k, MOBILITY] = 0.0
            tab[k, FIRST_X], tab[k, FIRST_Y] = tab[k, X], tab[k, Y]
        if not tab[k, MOVING_TIME] >= prm[P_MOVING_TIME]:
            speed = 0.0
        moved = np.hypot(tab[k, X] - tab[k, FIRST_X], tab[k, Y] - tab[k, FIRST_Y])
        age_s = (stamp - np.int64(tab[k, BORN])) * 1e-9
        confirmed = tab[k, CONFIRMED] != 0
        dynamic = tab[k, MOBILITY] == MOBILITY_DYNAMIC or (
            confirmed and moved > prm[P_MOVING_DISTANCE] and speed > prm[P_MOVING_SPEED]
        )
        if dynamic:
            mob = 1
        elif tab[k, SIZE] > prm[P_D_MAX] or age_s >= prm[P_UNDEFINED_WINDOW]:
            mob = 0
        else:
            mob = 2
        person, leg = tab[k, VOTES + K_PERSON], tab[k, VOTES + K_LEG]
        circle, rect, blob = tab[k, VOTES + K_CIRCLE], tab[k, VOTES + K_RECT], tab[k, VOTES + K_BLOB]
        total = person + leg + circle + rect + blob
        walking = tab[k, LEAD_LEFT] != 0 and tab[k, LEAD_RIGHT] != 0
        if person + leg >= prm[P_PERSON_VOTES] * max(total, 1.0):
            if walking and person > 0:
                cls = CLASS_PERSON
            elif person == 0 and not dynamic:
                cls = CLASS_CIRCLE_OBJECT
            else:
                cls = CLASS_UNKNOWN
        elif circle + rect + blob == 0:
            cls = CLASS_UNKNOWN
        elif circle >= rect and circle >= blob:
            cls = CLASS_CIRCLE_OBJECT
        elif rect >= blob:
            cls = CLASS_RECTANGULAR_OBJECT
        else:
            cls = CLASS_UNKNOWN
        tab[k, MOBILITY] = mob
        if learned:
            if circle + rect + blob == 0:
                cls = CLASS_UNKNOWN
            elif circle >= rect and circle >= blob:
                cls = CLASS_CIRCLE_OBJECT
            elif rect >= blob:
                cls = CLASS_RECTANGULAR_OBJECT
            else:
                cls = CLASS_UNKNOWN
            if tab[k, IS_PERSON] != 0:
                if tab[k, LEG_SCORE] < prm[P_PERSON_MAINTAIN]:
                    tab[k, IS_PERSON] = 0.0
            elif confirmed and person >= prm[P_PERSON_PAIRS]:
                # its legs seen in free space once (a place, not a mobility), or evidence beyond doubt
                need = prm[P_PERSON_EVIDENCE] if tab[k, FREE] != 0 else prm[P_PERSON_EVIDENCE_UNFREE]
                if tab[k, LEG_SCORE] >= need:
                    tab[k, IS_PERSON] = 1.0
            if tab[k, IS_PERSON] != 0:
                cls = CLASS_PERSON
        tab[k, CLS] = cls
