// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <random>
#include <string>
#include <tuple>

#include "common/geometry/lie.hpp"
#include "common/io/trajectory.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb::io {
namespace {

namespace fs = std::filesystem;

Eigen::Isometry3d randomPose(std::mt19937_64& rng) {
    std::normal_distribution<double> n(0.0, 1.0);
    Vector6d xi;
    for (int k = 0; k < 6; ++k) xi(k) = n(rng);
    return lie::expSE3(xi);
}

Trajectory randomTrajectory(size_t count, double t0, double dt, uint64_t seed) {
    std::mt19937_64 rng(seed);
    Trajectory trajectory;
    for (size_t k = 0; k < count; ++k) {
        trajectory.push_back(StampedPose{t0 + dt * static_cast<double>(k), randomPose(rng)});
    }
    return trajectory;
}

double poseDifference(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
    return (a.matrix() - b.matrix()).cwiseAbs().maxCoeff();
}

void writeFile(const fs::path& path, const std::string& text) {
    std::ofstream out(path, std::ios::binary);
    out << text;
}

TEST(TumTrajectory, RoundTripIsExactTo1e9) {
    const fs::path dir = testing::freshTempDir("tum_round_trip");
    const Trajectory in = randomTrajectory(200, 1341836537.8070, 0.0333, 1);
    ASSERT_TRUE(writeTumTrajectory(dir / "t.txt", in).isOk());
    const Result<Trajectory> out = readTumTrajectory(dir / "t.txt");
    ASSERT_TRUE(out.isOk()) << out.status().toString();
    ASSERT_EQ(out->size(), in.size());
    double worst = 0.0;
    for (size_t k = 0; k < in.size(); ++k) {
        EXPECT_EQ((*out)[k].timestamp_s, in[k].timestamp_s);
        worst = std::max(worst, poseDifference((*out)[k].T_W_C, in[k].T_W_C));
    }
    EXPECT_LT(worst, 1e-9);
}

TEST(TumTrajectory, ReadsCommentsTabsCommasAndScalarLastQuaternion) {
    const fs::path dir = testing::freshTempDir("tum_parse");
    // qw is last: a 90 degree rotation about z is (0 0 sin45 cos45).
    const double s = std::sqrt(0.5);
    writeFile(dir / "t.txt", "# ground truth\n\n1.5 1 2 3 0 0 " + std::to_string(s) + " " +
                                 std::to_string(s) +
                                 "\r\n2.5\t4\t5\t6\t0\t0\t0\t1\n3.5,7,8,9,0,0,0,1\n");
    const Result<Trajectory> t = readTumTrajectory(dir / "t.txt");
    ASSERT_TRUE(t.isOk()) << t.status().toString();
    ASSERT_EQ(t->size(), 3u);
    EXPECT_EQ((*t)[0].timestamp_s, 1.5);
    EXPECT_EQ((*t)[2].timestamp_s, 3.5);
    EXPECT_TRUE((*t)[0].T_W_C.translation().isApprox(Eigen::Vector3d(1, 2, 3)));
    // Camera x axis maps to world y.
    EXPECT_LT(((*t)[0].T_W_C.linear() * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(),
              1e-6);
    EXPECT_TRUE((*t)[2].T_W_C.translation().isApprox(Eigen::Vector3d(7, 8, 9)));
}

/// Writes `text` as a TUM file and returns the read error (expects one).
Status tumError(const std::string& name, const std::string& text) {
    const fs::path dir = testing::freshTempDir("tum_error_" + name);
    writeFile(dir / "bad.txt", text);
    const Result<Trajectory> t = readTumTrajectory(dir / "bad.txt");
    EXPECT_FALSE(t.isOk()) << name;
    return t.status();
}

TEST(TumTrajectory, MalformedInputNamesFileLineAndProblem) {
    const std::string good = "0 0 0 0 0 0 0 1\n";
    Status s = tumError("columns", good + "# c\n1 0 0 0 0 0 1\n");
    EXPECT_EQ(s.code(), StatusCode::kCorrupt);
    EXPECT_NE(s.message().find("bad.txt:3:"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("expected 8 columns"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("found 7"), std::string::npos) << s.message();

    s = tumError("number", good + "1 0 0 zero 0 0 0 1\n");
    EXPECT_NE(s.message().find("bad.txt:2:"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("column 4 is not a number: 'zero'"), std::string::npos)
        << s.message();

    s = tumError("trailing", good + "1 0 0 0.5x 0 0 0 1\n");
    EXPECT_NE(s.message().find("'0.5x'"), std::string::npos) << s.message();

    s = tumError("nan", good + good + "2 0 nan 0 0 0 0 1\n");
    EXPECT_NE(s.message().find("bad.txt:3: column 3 is not finite"), std::string::npos)
        << s.message();

    s = tumError("quaternion", "0 0 0 0 0 0 0.5 0.5\n");
    EXPECT_NE(s.message().find("bad.txt:1: quaternion"), std::string::npos) << s.message();
    s = tumError("zero_quaternion", "0 0 0 0 0 0 0 0\n");
    EXPECT_NE(s.message().find("norm 0"), std::string::npos) << s.message();

    s = tumError("empty", "# nothing\n\n");
    EXPECT_NE(s.message().find("no poses"), std::string::npos) << s.message();

    const Result<Trajectory> missing = readTumTrajectory("/nonexistent/dir/gt.txt");
    ASSERT_FALSE(missing.isOk());
    EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
    EXPECT_NE(missing.status().message().find("/nonexistent/dir/gt.txt"), std::string::npos);
}

TEST(LogTrajectory, RoundTripAndIdentity) {
    const fs::path dir = testing::freshTempDir("log_round_trip");
    const Trajectory in = randomTrajectory(60, 0.0, 1.0, 2);
    ASSERT_TRUE(writeLogTrajectory(dir / "t.log", in).isOk());
    const Result<Trajectory> out = readLogTrajectory(dir / "t.log");
    ASSERT_TRUE(out.isOk()) << out.status().toString();
    ASSERT_EQ(out->size(), in.size());
    for (size_t k = 0; k < in.size(); ++k) {
        EXPECT_EQ((*out)[k].timestamp_s, static_cast<double>(k));
        EXPECT_LT(poseDifference((*out)[k].T_W_C, in[k].T_W_C), 1e-9);
    }
    // Written metadata is `k k k+1` (Redwood camera trajectory convention).
    std::ifstream file(dir / "t.log");
    std::string first;
    std::getline(file, first);
    EXPECT_EQ(first, "0 0 1");

    writeFile(dir / "identity.log", "7 7 8\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
    const Result<Trajectory> identity = readLogTrajectory(dir / "identity.log");
    ASSERT_TRUE(identity.isOk()) << identity.status().toString();
    ASSERT_EQ(identity->size(), 1u);
    EXPECT_EQ((*identity)[0].timestamp_s, 7.0);
    EXPECT_LT(poseDifference((*identity)[0].T_W_C, Eigen::Isometry3d::Identity()), 1e-15);
}

TEST(LogTrajectory, TumToLogToTumKeepsPoses) {
    const fs::path dir = testing::freshTempDir("tum_log_tum");
    const Trajectory in = randomTrajectory(40, 100.0, 0.5, 3);
    ASSERT_TRUE(writeTumTrajectory(dir / "a.txt", in).isOk());
    const Trajectory a = readTumTrajectory(dir / "a.txt").value();
    ASSERT_TRUE(writeLogTrajectory(dir / "b.log", a).isOk());
    const Trajectory b = readLogTrajectory(dir / "b.log").value();
    ASSERT_TRUE(writeTumTrajectory(dir / "c.txt", b).isOk());
    const Trajectory c = readTumTrajectory(dir / "c.txt").value();
    ASSERT_EQ(c.size(), in.size());
    for (size_t k = 0; k < in.size(); ++k) {
        EXPECT_EQ(c[k].timestamp_s, static_cast<double>(k));  // .log stamps are frame indices
        EXPECT_LT(poseDifference(c[k].T_W_C, in[k].T_W_C), 1e-9);
    }
}

Status logError(const std::string& name, const std::string& text) {
    const fs::path dir = testing::freshTempDir("log_error_" + name);
    writeFile(dir / "bad.log", text);
    const Result<Trajectory> t = readLogTrajectory(dir / "bad.log");
    EXPECT_FALSE(t.isOk()) << name;
    return t.status();
}

TEST(LogTrajectory, MalformedInputNamesFileLineAndProblem) {
    const std::string entry = "0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n";
    Status s = logError("truncated", entry + "1 1 2\n1 0 0 0\n0 1 0 0\n");
    EXPECT_EQ(s.code(), StatusCode::kCorrupt);
    EXPECT_NE(s.message().find("truncated .log entry"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("starting at line 6"), std::string::npos) << s.message();

    s = logError("metadata", entry + "1 1.5 2\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
    EXPECT_NE(s.message().find("bad.log:6: metadata column 2 is not an integer"), std::string::npos)
        << s.message();

    s = logError("row", entry + "1 1 2\n1 0 0 0\n0 1 0\n0 0 1 0\n0 0 0 1\n");
    EXPECT_NE(s.message().find("bad.log:8: expected 4 columns"), std::string::npos) << s.message();

    s = logError("nan", "0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 nan\n0 0 0 1\n");
    EXPECT_NE(s.message().find("bad.log:4: column 4 is not finite"), std::string::npos)
        << s.message();

    s = logError("scaled", "0 0 1\n2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
    EXPECT_NE(s.message().find("bad.log:1: the 4x4 matrix"), std::string::npos) << s.message();

    s = logError("last_row", "0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n");
    EXPECT_NE(s.message().find("not a rigid transform"), std::string::npos) << s.message();
}

TEST(RegistrationLog, RoundTripKeepsMetadataAndTransforms) {
    const fs::path dir = testing::freshTempDir("registration_log");
    std::mt19937_64 rng(4);
    std::vector<RegistrationEntry> in;
    for (int k = 0; k < 10; ++k) in.push_back({k, k + 3, 14, randomPose(rng)});
    ASSERT_TRUE(writeRegistrationLog(dir / "r.log", in).isOk());
    const auto out = readRegistrationLog(dir / "r.log");
    ASSERT_TRUE(out.isOk()) << out.status().toString();
    ASSERT_EQ(out->size(), in.size());
    for (size_t k = 0; k < in.size(); ++k) {
        EXPECT_EQ((*out)[k].i, in[k].i);
        EXPECT_EQ((*out)[k].j, in[k].j);
        EXPECT_EQ((*out)[k].num_fragments, 14);
        EXPECT_LT(poseDifference((*out)[k].T_i_j, in[k].T_i_j), 1e-9);
    }
    // No accepted pairs is a valid (empty) registration result.
    ASSERT_TRUE(writeRegistrationLog(dir / "empty.log", {}).isOk());
    const auto empty = readRegistrationLog(dir / "empty.log");
    ASSERT_TRUE(empty.isOk());
    EXPECT_TRUE(empty->empty());
}

TEST(InformationFile, RoundTripIsExact) {
    const fs::path dir = testing::freshTempDir("info");
    std::mt19937_64 rng(5);
    std::normal_distribution<double> n(0.0, 100.0);
    std::vector<InformationEntry> in;
    for (int k = 0; k < 5; ++k) {
        Matrix6d A;
        for (int r = 0; r < 6; ++r) {
            for (int c = 0; c < 6; ++c) A(r, c) = n(rng);
        }
        in.push_back({k, k + 1, 5, A * A.transpose()});
    }
    ASSERT_TRUE(writeInformationFile(dir / "r.info", in).isOk());
    const auto out = readInformationFile(dir / "r.info");
    ASSERT_TRUE(out.isOk()) << out.status().toString();
    ASSERT_EQ(out->size(), in.size());
    for (size_t k = 0; k < in.size(); ++k) {
        EXPECT_EQ((*out)[k].i, in[k].i);
        EXPECT_EQ((*out)[k].j, in[k].j);
        EXPECT_EQ((*out)[k].information, in[k].information);  // shortest exact decimal form
    }
    writeFile(dir / "short.info", "0 1 5\n1 0 0 0 0 0\n0 1 0 0 0 0\n");
    const auto truncated = readInformationFile(dir / "short.info");
    ASSERT_FALSE(truncated.isOk());
    EXPECT_NE(truncated.status().message().find("truncated .info entry"), std::string::npos)
        << truncated.status().message();
}

/// A literal transcription of TUM associate.py (all pairs, sort by (diff, a, b), greedy).
std::vector<std::pair<size_t, size_t>> associateReference(const std::vector<double>& a,
                                                          const std::vector<double>& b,
                                                          double max_difference, double offset) {
    std::vector<std::tuple<double, double, double, size_t, size_t>> potential;
    for (size_t i = 0; i < a.size(); ++i) {
        for (size_t j = 0; j < b.size(); ++j) {
            const double d = std::abs(a[i] - (b[j] + offset));
            if (d < max_difference) potential.emplace_back(d, a[i], b[j], i, j);
        }
    }
    std::sort(potential.begin(), potential.end());
    std::vector<bool> used_a(a.size()), used_b(b.size());
    std::vector<std::pair<size_t, size_t>> matches;
    for (const auto& [d, sa, sb, i, j] : potential) {
        if (used_a[i] || used_b[j]) continue;
        used_a[i] = used_b[j] = true;
        matches.emplace_back(i, j);
    }
    std::sort(matches.begin(), matches.end());
    return matches;
}

TEST(Associate, GreedyClosestFirstAndUnique) {
    // b[0] is 10 ms from a[0] but only 2 ms from a[1]: associate.py gives it to a[1], and a[0]
    // stays unmatched (no per-a nearest neighbour).
    const auto m = associate({0.000, 0.012}, {0.010}, 0.02, 0.0);
    ASSERT_EQ(m.size(), 1u);
    EXPECT_EQ(m[0], std::make_pair(size_t{1}, size_t{0}));
    // The bound is strict, as in associate.py.
    EXPECT_TRUE(associate({0.0}, {0.5}, 0.5, 0.0).empty());
    EXPECT_EQ(associate({0.0}, {0.5}, 0.5000001, 0.0).size(), 1u);
    // The offset is added to b.
    const auto shifted = associate({10.0, 11.0}, {0.0, 1.0, 2.0}, 0.02, 10.0);
    ASSERT_EQ(shifted.size(), 2u);
    EXPECT_EQ(shifted[0], std::make_pair(size_t{0}, size_t{0}));
    EXPECT_EQ(shifted[1], std::make_pair(size_t{1}, size_t{1}));
    // Frame indices as stamps match exactly.
    EXPECT_EQ(associate({0, 1, 2, 3}, {3, 2, 1}, 0.02).size(), 3u);
}

TEST(Associate, MatchesLiteralAssociatePyOnRandomStamps) {
    std::mt19937_64 rng(6);
    std::uniform_real_distribution<double> u(0.0, 10.0);
    for (int trial = 0; trial < 20; ++trial) {
        std::vector<double> a(300), b(250);
        for (double& s : a) s = u(rng);
        for (double& s : b) s = u(rng);
        const double offset = trial % 2 == 0 ? 0.0 : 0.013;
        const auto ours = associate(a, b, 0.02, offset);
        EXPECT_EQ(ours, associateReference(a, b, 0.02, offset)) << "trial " << trial;
        EXPECT_GT(ours.size(), 100u);
    }
}

TEST(PoseAt, InterpolatesInsideAndRefusesOutsideOrAcrossGaps) {
    std::mt19937_64 rng(7);
    Trajectory t = {{1.0, randomPose(rng)}, {2.0, randomPose(rng)}, {5.0, randomPose(rng)}};
    ASSERT_TRUE(poseAt(t, 1.0, 0.5).has_value());
    EXPECT_LT(poseDifference(*poseAt(t, 1.0, 0.5), t[0].T_W_C), 1e-15);
    EXPECT_LT(poseDifference(*poseAt(t, 2.0, 0.5), t[1].T_W_C), 1e-15);
    const auto mid = poseAt(t, 1.25, 1.0);
    ASSERT_TRUE(mid.has_value());
    EXPECT_LT(poseDifference(*mid, lie::interpolate(t[0].T_W_C, t[1].T_W_C, 0.25)), 1e-12);
    EXPECT_FALSE(poseAt(t, 0.999, 10.0).has_value());
    EXPECT_FALSE(poseAt(t, 5.001, 10.0).has_value());
    EXPECT_FALSE(poseAt(t, 3.0, 2.0).has_value());  // neighbours 3 s apart
    EXPECT_TRUE(poseAt(t, 3.0, 3.0).has_value());
    EXPECT_FALSE(poseAt({}, 1.0, 1.0).has_value());
}

TEST(SharedData, ReadsTumGroundTruth) {
    // The macro's first argument must be called `path` (it also names the type).
    PLUMB_REQUIRE_SHARED_DATA(path, "tum-fr3-structure-notexture-far/groundtruth.txt");
    const Result<Trajectory> gt = readTumTrajectory(path);
    ASSERT_TRUE(gt.isOk()) << gt.status().toString();
    EXPECT_EQ(gt->size(), 2729u);
    EXPECT_DOUBLE_EQ(gt->front().timestamp_s, 1341836537.8070);
    EXPECT_TRUE(gt->front().T_W_C.translation().isApprox(Eigen::Vector3d(-1.2432, 1.9219, 1.0547)));
    for (const StampedPose& p : *gt) ASSERT_TRUE(lie::isValidPose(p.T_W_C, 1e-12));
}

TEST(SharedData, ReadsIclNuimGroundTruth) {
    PLUMB_REQUIRE_SHARED_DATA(path, "icl-nuim-office-kt0/groundtruth.txt");
    const Result<Trajectory> icl_gt = readTumTrajectory(path);
    ASSERT_TRUE(icl_gt.isOk()) << icl_gt.status().toString();
    EXPECT_EQ(icl_gt->front().timestamp_s, 2.0);  // frame index N of depth/N.png
    EXPECT_NEAR(icl_gt->front().T_W_C.translation().z(), -2.5, 1e-12);
}

// ---- Open3D interoperability (python3-open3d as the oracle) ----

const char* kPython = "/usr/bin/python3";

bool open3dAvailable() {
    const std::string cmd = std::string(kPython) + " -c 'import open3d' > /dev/null 2>&1";
    return std::system(cmd.c_str()) == 0;
}

/// Reads `rows` x 4 whitespace-separated numbers as a stack of 4x4 matrices.
std::vector<Eigen::Matrix4d> readMatrices(const fs::path& path) {
    std::ifstream in(path);
    std::vector<Eigen::Matrix4d> out;
    Eigen::Matrix4d M;
    int n = 0;
    double v = 0.0;
    while (in >> v) {
        M(n / 4, n % 4) = v;
        if (++n == 16) {
            out.push_back(M);
            n = 0;
        }
    }
    return out;
}

TEST(LogTrajectoryOpen3d, Open3dReadsOursAndWeReadOpen3ds) {
    if (!open3dAvailable()) {
        if (testing::runningInCi()) FAIL() << "python3-open3d missing";
        GTEST_SKIP() << "python3-open3d not importable";
    }
    const fs::path dir = testing::freshTempDir("log_open3d");
    const Trajectory ours = randomTrajectory(30, 0.0, 1.0, 8);
    ASSERT_TRUE(writeLogTrajectory(dir / "plumb.log", ours).isOk());
    const std::string script = R"(import numpy as np, open3d as o3d, sys
d = sys.argv[1]
# Read plumb's .log with Open3D: extrinsic is world->camera, the inverse of the .log matrix.
traj = o3d.io.read_pinhole_camera_trajectory(d + "/plumb.log")
np.savetxt(d + "/o3d_read.txt",
           np.vstack([np.linalg.inv(p.extrinsic) for p in traj.parameters]), fmt="%.17g")
# Write a .log with Open3D from random rigid extrinsics.
rng = np.random.default_rng(3)
out = o3d.camera.PinholeCameraTrajectory()
params, poses = [], []
for k in range(20):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    if np.linalg.det(q) < 0: q[:, 0] = -q[:, 0]
    T = np.eye(4); T[:3, :3] = q; T[:3, 3] = rng.uniform(-5, 5, 3)
    p = o3d.camera.PinholeCameraParameters()
    p.intrinsic = o3d.camera.PinholeCameraIntrinsic(640, 480, 525.0, 525.0, 319.5, 239.5)
    p.extrinsic = np.linalg.inv(T)
    params.append(p); poses.append(T)
out.parameters = params
o3d.io.write_pinhole_camera_trajectory(d + "/o3d.log", out)
np.savetxt(d + "/o3d_expected.txt", np.vstack(poses), fmt="%.17g")
)";
    writeFile(dir / "o3d.py", script);
    const std::string cmd = std::string(kPython) + " " + (dir / "o3d.py").string() + " " +
                            dir.string() + " > /dev/null 2>&1";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;

    // Open3D's view of our file (its extrinsic is world->camera; the script inverts it).
    const std::vector<Eigen::Matrix4d> read_by_open3d = readMatrices(dir / "o3d_read.txt");
    ASSERT_EQ(read_by_open3d.size(), ours.size());
    for (size_t k = 0; k < ours.size(); ++k) {
        EXPECT_LT((read_by_open3d[k] - ours[k].T_W_C.matrix()).cwiseAbs().maxCoeff(), 1e-9) << k;
    }
    // Our view of Open3D's file (it prints 8 decimals).
    const Result<Trajectory> theirs = readLogTrajectory(dir / "o3d.log");
    ASSERT_TRUE(theirs.isOk()) << theirs.status().toString();
    const std::vector<Eigen::Matrix4d> expected = readMatrices(dir / "o3d_expected.txt");
    ASSERT_EQ(theirs->size(), expected.size());
    ASSERT_EQ(expected.size(), 20u);
    for (size_t k = 0; k < expected.size(); ++k) {
        EXPECT_EQ((*theirs)[k].timestamp_s, static_cast<double>(k));
        EXPECT_LT(((*theirs)[k].T_W_C.matrix() - expected[k]).cwiseAbs().maxCoeff(), 1e-7) << k;
    }
}

}  // namespace
}  // namespace plumb::io
