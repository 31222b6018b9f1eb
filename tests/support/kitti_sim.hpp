#pragma once

// The drift simulator on the KITTI ground truth shipped in data/kitti (sequences 00-02 and
// 04-12 of the poses there), with the committed defaults of SimOptions::kitti.

#include <limits>
#include <string>

#include "geodrift/sim/drift_simulator.hpp"
#include "geodrift/sim/kitti_protocol.hpp"

namespace geodrift::test {

/// Sequence `seq` ("02", "08", ...) simulated with SimOptions::kitti(seq, seed), frames
/// [0, last_frame).
inline sim::SimulatedSequence simulate_kitti(const std::string& seq, unsigned seed,
                                             int last_frame = std::numeric_limits<int>::max()) {
  const std::string dir = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti";
  const std::string calib =
      dir + (std::stoi(seq) <= 2 ? "/calib_seq00-02.txt" : "/calib_seq04-12.txt");
  const sim::KittiSequence kitti = sim::load_kitti_sequence(dir + "/poses/" + seq + ".txt", calib,
                                                            dir + "/times/" + seq + ".txt");
  sim::SimOptions so = sim::SimOptions::kitti(seq, seed);
  so.last_frame = last_frame;
  return sim::simulate(kitti, so);
}

}  // namespace geodrift::test
