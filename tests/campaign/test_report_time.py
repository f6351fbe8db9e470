"""A campaign report's total run time reads in the unit that shows it."""

from cdpr_twin.campaign.report import cpu_time


def test_short_campaigns_read_in_seconds_long_ones_in_minutes():
    # 18 runs of one tick took 18.6 s: in minutes to one decimal that read "0.3 CPU-min", and a
    # single short run "0.0 CPU-min"
    assert cpu_time(2.4) == "2.4 CPU-s" and cpu_time(18.6) == "18.6 CPU-s"
    assert cpu_time(486.0) == "8.1 CPU-min"  # the committed 1 000-robot report's figure
