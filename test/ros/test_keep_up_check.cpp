// KeepUpCheck: one warning, early, exactly when frames cost more than the workers have per arriving frame.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "hpds_node/KeepUpCheck.hpp"

namespace {

using hpds_node::KeepUpCheck;

bool contains(const std::string &text, const std::string &part) { return text.find(part) != std::string::npos; }

// Frames arriving every `period` seconds, each taking `cost` seconds; returns every non-empty verdict.
std::vector<std::string> run(KeepUpCheck &check, double period, double cost, int frames) {
  std::vector<std::string> said;
  for (int i = 0; i < frames; ++i) {
    check.arrived(100.0 + period * i);
    std::string text = check.processed(i == 0 ? 50 * cost : cost);  // the first frame is always slow
    if (!text.empty()) said.push_back(std::move(text));
  }
  return said;
}

TEST(KeepUpCheck, SlowFramesAreReportedOnceWithTheNumbersAndWhatToSet) {
  hpds::HpdsConfig config;  // the shipped defaults: spacing 0.1 m, normals on, offset 2, one thread
  KeepUpCheck check(config, 1, 8);
  const auto said = run(check, 0.1, 0.25, 40);
  ASSERT_EQ(said.size(), 1u);
  const std::string &w = said.front();
  EXPECT_TRUE(contains(w, "cannot keep up")) << w;
  EXPECT_TRUE(contains(w, "every 100 ms (10.0 Hz)")) << w;
  EXPECT_TRUE(contains(w, "take 250 ms")) << w;
  EXPECT_TRUE(contains(w, "about 60% of the frames")) << w;  // 1 - 100/250
  EXPECT_TRUE(contains(w, "output.spacing (now 0.1 m)")) << w;
  EXPECT_TRUE(contains(w, "normals.neighborhood_level_offset 0 (now 2")) << w;
  EXPECT_TRUE(contains(w, "threads (now 1)")) << w;
  EXPECT_TRUE(check.judged());
}

// A transform that never comes makes the worker wait ros/tf_timeout per frame, and the queue overflows: the warning
// says so, instead of only advising sampling settings that cannot help.
TEST(KeepUpCheck, WaitingForTransformsIsNamedWhenItTakesThePeriod) {
  KeepUpCheck check(hpds::HpdsConfig{}, 1, 8, 0.1);
  for (int i = 0; i < 6; ++i) {
    check.arrived(0.05 * i);                // 20 Hz
    EXPECT_EQ(check.processed(0.0, 0.1), "");  // dropped as no_transform after the full wait
  }
  const std::string w = check.dropped();
  EXPECT_TRUE(contains(w, "wait 100 ms each for their transforms")) << w;
  EXPECT_TRUE(contains(w, "ros/tf_timeout, now 0.1 s")) << w;
  // A transform that comes late needs room for the frames that arrive during the wait: 100 ms at 50 ms periods.
  EXPECT_TRUE(contains(w, "a ros/queue_size of at least 3 (now 1)")) << w;

  // 465 ms waits at 10 Hz, the queue of 1 (a lidar odometry half a second behind): 6 keeps every frame.
  KeepUpCheck late(hpds::HpdsConfig{}, 1, 8, 0.7, 1);
  for (int i = 0; i < 3; ++i) {
    late.arrived(0.1 * i);
    EXPECT_EQ(late.processed(0.02, 0.465), "") << i;
  }
  late.arrived(0.3);
  const std::string said = late.dropped();
  EXPECT_TRUE(contains(said, "wait 465 ms each")) << said;
  EXPECT_TRUE(contains(said, "a ros/queue_size of at least 6 (now 1)")) << said;

  // A transform lagging 90 ms behind 10 Hz frames that take 14 ms: the worker keeps up, nothing is said.
  KeepUpCheck lagging(hpds::HpdsConfig{}, 1, 8, 0.1);
  for (int i = 0; i < 40; ++i) {
    lagging.arrived(0.1 * i);
    EXPECT_EQ(lagging.processed(0.014, 0.086), "") << i;
  }
  EXPECT_TRUE(lagging.judged());
}

TEST(KeepUpCheck, TheVerdictComesWithTheNinthFrame) {
  KeepUpCheck check(hpds::HpdsConfig{}, 1, 8);
  for (int i = 0; i < 8; ++i) {
    check.arrived(0.1 * i);
    EXPECT_EQ(check.processed(0.3), "") << "frame " << i;  // frame 0 is left out, frames 1..7 are not yet 8
  }
  check.arrived(0.8);
  EXPECT_NE(check.processed(0.3), "");
  check.arrived(0.9);
  EXPECT_EQ(check.processed(0.3), "") << "said twice";
}

TEST(KeepUpCheck, FastFramesAndEnoughWorkersSayNothing) {
  {
    KeepUpCheck check(hpds::HpdsConfig{}, 1, 8);
    EXPECT_TRUE(run(check, 0.1, 0.06, 40).empty());
    EXPECT_TRUE(check.judged());
  }
  {
    // 250 ms per frame, but four workers have 400 ms per arriving frame.
    KeepUpCheck check(hpds::HpdsConfig{}, 4, 8);
    EXPECT_TRUE(run(check, 0.1, 0.25, 40).empty());
  }
  {
    // Two workers have 200 ms: not enough for 250 ms.
    KeepUpCheck check(hpds::HpdsConfig{}, 2, 8);
    const auto said = run(check, 0.1, 0.25, 40);
    ASSERT_EQ(said.size(), 1u);
    EXPECT_TRUE(contains(said.front(), "2 workers")) << said.front();
    EXPECT_TRUE(contains(said.front(), "about 20% of the frames")) << said.front();
  }
}

TEST(KeepUpCheck, OneSlowFrameAmongFastOnesIsNoVerdict) {
  KeepUpCheck check(hpds::HpdsConfig{}, 1, 8);
  for (int i = 0; i < 20; ++i) {
    check.arrived(0.1 * i);
    EXPECT_EQ(check.processed(i == 5 ? 2.0 : 0.04), "");
  }
  EXPECT_TRUE(check.judged());
}

TEST(KeepUpCheck, NoPeriodNoVerdict) {
  // A single message (or all at one instant, a burst) gives no input period to compare with.
  KeepUpCheck check(hpds::HpdsConfig{}, 1, 3);
  check.arrived(5.0);
  for (int i = 0; i < 10; ++i) EXPECT_EQ(check.processed(1.0), "");
  EXPECT_FALSE(check.judged());
  check.arrived(5.0);  // a burst: a zero gap is no period either
  EXPECT_EQ(check.processed(1.0), "");
  EXPECT_FALSE(check.judged());
  check.arrived(5.1);
  EXPECT_NE(check.processed(1.0), "");
}

TEST(KeepUpCheck, TheFirstOverloadDropIsReportedOnceWithWhatWasMeasured) {
  KeepUpCheck check(hpds::HpdsConfig{}, 1, 8);
  for (int i = 0; i < 9; ++i) {
    check.arrived(0.1 * i);
    EXPECT_EQ(check.processed(i == 8 ? 0.35 : 0.06), "");
  }
  // The 0.35 s frame made the queue overflow; with the verdict's 8 costs measured, said at once.
  const std::string w = check.dropped();
  // The usual rate keeps up (60 ms every 100 ms): a moment behind, not "cannot keep up" beside numbers that do.
  EXPECT_TRUE(contains(w, "fell behind the input for a moment")) << w;
  EXPECT_FALSE(contains(w, "cannot keep up")) << w;
  EXPECT_TRUE(contains(w, "which keeps up: frames came faster than that (a burst) or one took longer")) << w;
  EXPECT_TRUE(contains(w, "a frame was dropped")) << w;
  EXPECT_TRUE(contains(w, "every 100 ms (10.0 Hz) and take 60 ms each")) << w;
  EXPECT_TRUE(contains(w, "350 ms at most")) << w;
  EXPECT_FALSE(contains(w, "will be dropped")) << "the median keeps up: no share of frames lost to announce";
  EXPECT_EQ(check.dropped(), "") << "said twice";
  for (int i = 9; i < 30; ++i) {
    check.arrived(0.1 * i);
    EXPECT_EQ(check.processed(0.3), "") << "a verdict after the warning must stay silent";
  }
  EXPECT_TRUE(check.judged());

  // A drop before enough was measured (20 Hz frames of 150 ms: the queue overflows while the first, slower one
  // runs) is said once the verdict's 8 costs are in, once: said with the first cost, a trial quoted "median of 1
  // frames" and a share of lost frames that one slow frame made up.
  KeepUpCheck early(hpds::HpdsConfig{}, 1, 8);
  early.arrived(0.0);
  early.arrived(0.05);
  EXPECT_TRUE(early.warmingUp());
  early.arrived(0.10);
  EXPECT_EQ(early.dropped(), "");
  EXPECT_EQ(early.processed(2.0), "") << "the first frame pays for allocations: no measure of the cost";
  EXPECT_FALSE(early.warmingUp());
  std::string e;
  for (int k = 1; k <= 8; ++k) {
    early.arrived(0.10 + 0.05 * k);
    if (k > 1) {
      EXPECT_EQ(early.dropped(), "") << k;  // the queue keeps overflowing: still too little measured
    }
    e = early.processed(0.15);
    if (k < 8) {
      EXPECT_EQ(e, "") << "only " << k << " costs measured";
    }
  }
  EXPECT_TRUE(contains(e, "cannot keep up")) << e;
  EXPECT_TRUE(contains(e, "a frame was dropped")) << e;
  EXPECT_TRUE(contains(e, "every 50 ms (20.0 Hz) and take 150 ms each (median of 8 frames")) << e;
  EXPECT_TRUE(contains(e, "output.spacing (now 0.1 m)")) << e;
  EXPECT_EQ(early.dropped(), "") << "said twice";
  early.arrived(0.60);
  EXPECT_EQ(early.processed(0.15), "") << "said twice";

  // Transform lookups that return at once (microseconds) are no measurement: found with VLS-128 frames at the
  // defaults, the pending drop was spent on "none has been processed yet" and the cost was never said.
  KeepUpCheck instant(hpds::HpdsConfig{}, 1, 8);
  instant.arrived(0.0);
  instant.arrived(0.05);
  instant.arrived(0.10);
  EXPECT_EQ(instant.dropped(), "");
  EXPECT_EQ(instant.processed(2.0, 2e-5), "") << "a 20 us lookup is no wait worth a warning";
  std::string said;
  for (int k = 1; k <= 8; ++k) {
    instant.arrived(0.10 + 0.05 * k);
    said = instant.processed(0.15, 2e-5);
  }
  EXPECT_TRUE(contains(said, "every 50 ms (20.0 Hz) and take 150 ms each")) << said;
  EXPECT_FALSE(contains(said, "for their transforms")) << said;

  // The first frame waits for a transform that never comes while the queue overflows: said when that wait ends,
  // naming it, not as sampling advice alone.
  hpds::HpdsConfig map;
  map.mode = hpds::Mode::Map;
  KeepUpCheck no_tf(map, 1, 8, 0.5);
  for (int i = 0; i < 4; ++i) no_tf.arrived(0.1 * i);
  EXPECT_EQ(no_tf.dropped(), "");
  const std::string t = no_tf.processed(0.0, 0.5);
  EXPECT_TRUE(contains(t, "every 100 ms (10.0 Hz) and none has been processed yet")) << t;
  EXPECT_TRUE(contains(t, "wait 500 ms each for their transforms")) << t;
  EXPECT_TRUE(contains(t, "no sampling setting shortens that wait")) << t;
  EXPECT_FALSE(contains(t, "no processing time measured")) << t;
  // Map mode at the defaults builds no level for the normals: it averages the frame's points, as scan mode.
  EXPECT_TRUE(contains(t, "(now 2: finer detail the normals average)")) << t;

  // After a failed verdict, drops add nothing.
  KeepUpCheck slow(hpds::HpdsConfig{}, 1, 8);
  ASSERT_EQ(run(slow, 0.1, 0.25, 20).size(), 1u);
  EXPECT_EQ(slow.dropped(), "");
}

// The first frame pays for the node's allocations: frames dropped behind it on a stream the node then keeps up
// with are the start-up's, and nothing is said (a trial saw a warning on every start of the node at the defaults).
// When the frames after it do not keep up, that is said as before.
TEST(KeepUpCheck, DropsBehindTheFirstFrameAloneAreTheStartUps) {
  KeepUpCheck check(hpds::HpdsConfig{}, 1, 8);
  for (int i = 0; i < 3; ++i) check.arrived(0.1 * i);
  EXPECT_TRUE(check.warmingUp());
  EXPECT_EQ(check.dropped(), "");
  EXPECT_EQ(check.processed(0.18), "");
  EXPECT_FALSE(check.warmingUp());
  for (int i = 3; i < 40; ++i) {
    check.arrived(0.1 * i);
    EXPECT_EQ(check.processed(0.05), "") << i;
  }
  EXPECT_TRUE(check.judged());
  EXPECT_FALSE(check.warned());

  KeepUpCheck slow(hpds::HpdsConfig{}, 1, 8);
  for (int i = 0; i < 3; ++i) slow.arrived(0.1 * i);
  EXPECT_EQ(slow.dropped(), "");
  EXPECT_EQ(slow.processed(0.5), "");
  std::vector<std::string> said;
  for (int i = 3; i < 40; ++i) {
    slow.arrived(0.1 * i);
    if (std::string w = slow.processed(0.15); !w.empty()) said.push_back(w);
  }
  ASSERT_EQ(said.size(), 1u);
  EXPECT_TRUE(contains(said[0], "cannot keep up")) << said[0];
  EXPECT_TRUE(contains(said[0], "a frame was dropped")) << said[0];

  // A drop after the first frame is no start-up's, even when the frames keep up on the median.
  KeepUpCheck later(hpds::HpdsConfig{}, 1, 8);
  for (int i = 0; i < 3; ++i) {
    later.arrived(0.1 * i);
    EXPECT_EQ(later.processed(i == 0 ? 0.5 : 0.05), "");
  }
  EXPECT_EQ(later.dropped(), "");
  std::string w;
  for (int i = 3; i < 10 && w.empty(); ++i) {
    later.arrived(0.1 * i);
    w = later.processed(0.05);
  }
  EXPECT_TRUE(contains(w, "fell behind the input for a moment")) << w;
}

// 10 Hz frames of 60 ms (the workers keep up, the verdict says nothing), then `after` more arrivals `period` apart,
// the first `pause` seconds after the last 10 Hz one.
void keptUpThen(KeepUpCheck &check, double pause, double period, int after) {
  for (int i = 0; i < 64; ++i) {
    check.arrived(0.1 * i);
    EXPECT_EQ(check.processed(i == 0 ? 3.0 : 0.06), "") << i;
  }
  ASSERT_TRUE(check.judged());
  for (int k = 0; k < after; ++k) {
    check.arrived(6.3 + pause + period * k);
    EXPECT_EQ(check.processed(0.06), "");
  }
}

// The gaps of the last 64 arrivals were the period: a drop soon after the input sped up quoted the old rate and
// called an input the worker can no longer follow a moment's lag.
TEST(KeepUpCheck, ADropAfterTheRateRoseQuotesTheNewRate) {
  KeepUpCheck check(hpds::HpdsConfig{}, 1, 8);
  keptUpThen(check, 0.05, 0.05, 4);  // 20 Hz from the 65th frame on
  const std::string w = check.dropped();
  EXPECT_TRUE(contains(w, "cannot keep up")) << w;
  EXPECT_TRUE(contains(w, "every 50 ms (20.0 Hz) and take 60 ms each")) << w;
  EXPECT_TRUE(contains(w, "about 17% of the frames will be dropped")) << w;  // 1 - 50/60
}

// The same after a pause (a bag paused, a sensor restarted) that ends at another rate; a pause that ends at the old
// rate is one long gap, which leaves the period as it was.
TEST(KeepUpCheck, ADropAfterAPauseQuotesTheRateTheInputResumedAt) {
  KeepUpCheck faster(hpds::HpdsConfig{}, 1, 8);
  keptUpThen(faster, 30.0, 0.04, 4);  // 25 Hz after 30 s without input
  const std::string w = faster.dropped();
  EXPECT_TRUE(contains(w, "cannot keep up")) << w;
  EXPECT_TRUE(contains(w, "every 40 ms (25.0 Hz)")) << w;

  KeepUpCheck same(hpds::HpdsConfig{}, 1, 8);
  keptUpThen(same, 30.0, 0.1, 5);
  const std::string s = same.dropped();
  EXPECT_TRUE(contains(s, "fell behind the input for a moment")) << s;
  EXPECT_TRUE(contains(s, "every 100 ms (10.0 Hz)")) << s;
}

// A stalled connection delivers the frames it held back to back: too few to fill the queue and the workers are no
// new rate, so the drop they cause is a moment behind the usual rate, as before.
TEST(KeepUpCheck, FramesDeliveredBackToBackAfterAStallKeepThePeriod) {
  KeepUpCheck check(hpds::HpdsConfig{}, 1, 8);
  keptUpThen(check, 0.3, 0.001, 3);  // two frames held back come with the third: it finds the queue full
  const std::string w = check.dropped();
  EXPECT_TRUE(contains(w, "fell behind the input for a moment")) << w;
  EXPECT_TRUE(contains(w, "every 100 ms (10.0 Hz)")) << w;

  // Two workers and two queued frames take four of them; the fifth is dropped.
  KeepUpCheck larger(hpds::HpdsConfig{}, 2, 8, 0.0, 2);
  keptUpThen(larger, 0.5, 0.001, 5);
  const std::string l = larger.dropped();
  EXPECT_TRUE(contains(l, "every 100 ms (10.0 Hz)")) << l;
  // The same queue after a rise to 40 Hz: five gaps in a row are the new rate.
  KeepUpCheck rose(hpds::HpdsConfig{}, 2, 8, 0.0, 2);
  keptUpThen(rose, 0.025, 0.025, 5);
  const std::string r = rose.dropped();
  EXPECT_TRUE(contains(r, "every 25 ms (40.0 Hz)")) << r;
  EXPECT_TRUE(contains(r, "cannot keep up")) << r;  // 60 ms a frame on two workers: 30 ms per frame
}

TEST(KeepUpCheck, AdviceFollowsTheConfig) {
  hpds::HpdsConfig config;
  config.mode = hpds::Mode::Map;
  config.normals.enabled = false;
  config.input.max_range = 80.0;
  config.output.spacing = 0.3;
  KeepUpCheck check(config, 1, 4);
  const auto said = run(check, 0.1, 0.5, 10);
  ASSERT_EQ(said.size(), 1u);
  const std::string &w = said.front();
  EXPECT_TRUE(contains(w, "output.spacing (now 0.3 m)")) << w;
  EXPECT_FALSE(contains(w, "normals.")) << w;
  EXPECT_FALSE(contains(w, "input.max_range")) << w;
  EXPECT_TRUE(contains(w, "map mode processes one frame at a time")) << w;
}

}  // namespace
