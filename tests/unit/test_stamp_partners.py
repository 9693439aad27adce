from stream_viz.collect.stamp_partners import stamp_partners

MS = 1_000_000


def test_topics_triggered_together_share_their_stamps():
    tick = [k * 200 * MS for k in range(10)]  # a 5 Hz trigger
    got = stamp_partners({"/left": tick, "/right": tick, "/imu": [k * 10 * MS + 3 for k in range(200)]})
    assert got == {"/left": {"/right": 1.0}, "/right": {"/left": 1.0}}


def test_a_known_pair_that_no_longer_shares_a_stamp_has_a_share_of_0():
    tick = [k * 200 * MS for k in range(10)]
    moved = [x + 41 * MS for x in tick]
    assert stamp_partners({"/left": tick, "/right": moved}) == {}
    got = stamp_partners({"/left": tick, "/right": moved}, {frozenset(("/left", "/right"))})
    assert got == {"/left": {"/right": 0.0}, "/right": {"/left": 0.0}}


def test_a_share_counts_only_stamps_inside_the_partner_s_span():
    pano = [k * 200 * MS for k in range(50, 60)]  # its newest 10: 10.0-11.8 s
    # a detector passing the panorama's header on now and then: its newest 10 span 0-11.8 s
    det = [k * 200 * MS for k in (0, 7, 15, 22, 30, 36, 41, 52, 55, 59)]
    got = stamp_partners({"/pano": pano, "/det": det})
    assert got == {"/det": {"/pano": 1.0}, "/pano": {"/det": 0.3}}
    # two of its stamps inside the panorama's span are too few to compare
    assert stamp_partners({"/pano": pano, "/det": det[:-1]}, {frozenset(("/pano", "/det"))}) \
        == {"/pano": {"/det": 0.333}}  # 2 of its 6 stamps in 0-11.0 s


def test_a_stamp_many_topics_carry_is_a_clock_s_tick_not_a_trigger():
    tick = [k * 100 * MS for k in range(10)]  # simulated time: every 10 Hz sensor on its steps
    many = {f"/s{i}": tick for i in range(16)}
    assert stamp_partners(many) == {}
    assert stamp_partners(dict(list(many.items())[:15]))["/s0"] == {f"/s{i}": 1.0 for i in range(1, 15)}
