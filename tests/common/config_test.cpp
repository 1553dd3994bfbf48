// SPDX-License-Identifier: Apache-2.0
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <iostream>
#include <limits>
#include <string>
#include <vector>

#include "common/config/config.hpp"
#include "common/config/registry.hpp"
#include "common/config/schema.hpp"
#include "tests/testing/shared_data.hpp"

namespace plumb {
namespace {

// A configuration that uses every supported field type, a nested section two levels deep and
// every kind of bound.
enum class Mode { kFast, kAccurate };

constexpr std::array<config::EnumName<Mode>, 2> kModeNames{{
    {Mode::kFast, "fast"},
    {Mode::kAccurate, "accurate"},
}};

struct VolumeConfig {
    /// Voxel edge length.
    double voxel_size_m = 0.01;
    /// Truncation distance in voxels.
    int truncation_voxels = 4;
    /// Maximum integration weight.
    float max_weight = 64.0f;
    bool operator==(const VolumeConfig&) const = default;
};

struct GridConfig {
    /// Number of blocks to preallocate.
    uint64_t block_budget = 1u << 16;
    /// Volume settings.
    VolumeConfig volume;
    bool operator==(const GridConfig&) const = default;
};

struct TestConfig {
    /// Human-readable name of the run.
    std::string name = "room \"A\"\ttab";
    /// Seed of every random choice.
    int64_t seed = 42;
    /// Whether to print diagnostics.
    bool verbose = false;
    /// Speed/accuracy trade-off.
    Mode mode = Mode::kFast;
    /// Gravity direction in the world frame.
    Eigen::Vector3d gravity_W = Eigen::Vector3d(0.0, 0.0, -9.81);
    /// Colour tint (float precision).
    Eigen::Vector3f tint = Eigen::Vector3f(0.1f, 0.2f, 0.3f);
    /// Pyramid level weights.
    std::vector<double> level_weights = {1.0, 0.5, 0.25};
    /// Frame indices to skip.
    std::vector<int64_t> skip_frames = {};
    /// Extra tags.
    std::vector<std::string> tags = {"a", "b"};
    /// Small float that needs full precision.
    float epsilon = 1e-7f;
    /// Grid settings.
    GridConfig grid;
    bool operator==(const TestConfig&) const = default;
};

void describe(config::Schema& s, VolumeConfig& c) {
    s.field("voxel_size_m", c.voxel_size_m, "TSDF voxel edge length", "m").positive().max(1.0);
    s.field("truncation_voxels", c.truncation_voxels, "truncation distance", "voxels").range(1, 16);
    s.field("max_weight", c.max_weight, "maximum integration weight").greaterThan(0).lessThan(1e9);
}

void describe(config::Schema& s, GridConfig& c) {
    s.field("block_budget", c.block_budget, "number of blocks to preallocate", "blocks").min(1);
    s.section("volume", c.volume, "the fused volume");
}

void describe(config::Schema& s, TestConfig& c) {
    s.field("name", c.name, "human-readable name of the run");
    s.field("seed", c.seed, "seed of every random choice");
    s.field("verbose", c.verbose, "print diagnostics");
    s.field("mode", c.mode, "speed/accuracy trade-off", kModeNames);
    s.field("gravity_W", c.gravity_W, "gravity in the world frame", "m/s^2");
    s.field("tint", c.tint, "colour tint").range(0.0, 1.0);
    s.field("level_weights", c.level_weights, "pyramid level weights").min(0.0);
    s.field("skip_frames", c.skip_frames, "frame indices to skip", "frames").min(0);
    s.field("tags", c.tags, "extra tags");
    s.field("epsilon", c.epsilon, "small float that needs full precision").positive();
    s.section("grid", c.grid, "voxel grid");
}

TEST(Config, LoadsEveryTypeFromToml) {
    TestConfig c;
    const Status st = config::loadString(R"(
name = "office"
seed = -7
verbose = true
mode = "accurate"
gravity_W = [0, -9.8, 0.5]
tint = [1, 0.5, 0]
level_weights = [2.0, 1]
skip_frames = [3, 5]
tags = []
epsilon = 2

[grid]
block_budget = 100

[grid.volume]
voxel_size_m = 0.004
truncation_voxels = 8
)",
                                         "test.toml", c);
    ASSERT_TRUE(st.isOk()) << st.toString();
    EXPECT_EQ(c.name, "office");
    EXPECT_EQ(c.seed, -7);
    EXPECT_TRUE(c.verbose);
    EXPECT_EQ(c.mode, Mode::kAccurate);
    EXPECT_EQ(c.gravity_W, Eigen::Vector3d(0.0, -9.8, 0.5));
    EXPECT_EQ(c.tint, Eigen::Vector3f(1.0f, 0.5f, 0.0f));
    EXPECT_EQ(c.level_weights, (std::vector<double>{2.0, 1.0}));
    EXPECT_EQ(c.skip_frames, (std::vector<int64_t>{3, 5}));
    EXPECT_TRUE(c.tags.empty());
    EXPECT_EQ(c.epsilon, 2.0f);
    EXPECT_EQ(c.grid.block_budget, 100u);
    EXPECT_EQ(c.grid.volume.voxel_size_m, 0.004);
    EXPECT_EQ(c.grid.volume.truncation_voxels, 8);
    EXPECT_EQ(c.grid.volume.max_weight, 64.0f);  // absent: default kept
}

TEST(Config, MisspelledKeyNamesKeyFileLineAndSuggestion) {
    const auto dir = testing::freshTempDir("config_misspelled");
    const auto path = dir / "fusion.toml";
    {
        std::ofstream out(path);
        out << "# fusion settings\n"
               "seed = 3\n"
               "\n"
               "[grid.volume]\n"
               "voxel_sise_m = 0.02\n";
    }
    TestConfig c;
    const Status st = config::loadFile(path, c);
    ASSERT_FALSE(st.isOk());
    EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(st.message(), path.string() +
                                ":5:1: unknown key 'grid.volume.voxel_sise_m' (did you mean "
                                "'grid.volume.voxel_size_m'?)");
    std::cout << "error: " << st.toString() << "\n";
    // Transactional: the valid `seed = 3` on line 2 was not applied either.
    EXPECT_EQ(c, TestConfig{});
}

TEST(Config, KeyInWrongSectionSuggestsFullPath) {
    TestConfig c;
    const Status st = config::loadString("block_budget = 5\n", "x.toml", c);
    ASSERT_FALSE(st.isOk());
    EXPECT_EQ(st.message(),
              "x.toml:1:1: unknown key 'block_budget' (did you mean 'grid.block_budget'?)");
    // Nothing close: no suggestion.
    const Status far = config::loadString("\n\ncompletely_different = 1\n", "y.toml", c);
    EXPECT_EQ(far.message(), "y.toml:3:1: unknown key 'completely_different'");
}

TEST(Config, TypeMismatchNamesKeyLineAndExpectedType) {
    TestConfig c;
    const Status st = config::loadString(
        "seed = 1.5\n"
        "[grid.volume]\n"
        "voxel_size_m = \"small\"\n"
        "truncation_voxels = 4000000000\n",
        "t.toml", c);
    ASSERT_FALSE(st.isOk());
    // Every problem is reported, sorted by line.
    EXPECT_EQ(st.message(),
              "t.toml:1:1: 'seed': expected an integer, got a float\n"
              "t.toml:3:1: 'grid.volume.voxel_size_m': expected a float, got a string (unit: m)\n"
              "t.toml:4:1: 'grid.volume.truncation_voxels': value 4000000000 does not fit in a "
              "32-bit integer (unit: voxels)");
    EXPECT_EQ(config::loadString("grid = 3\n", "u.toml", c).message(),
              "u.toml:1:1: 'grid' is a section: expected a table, got an integer");
    EXPECT_EQ(config::loadString("mode = \"slow\"\n", "v.toml", c).message(),
              "v.toml:1:1: 'mode': expected one of fast, accurate, got 'slow'");
    EXPECT_EQ(config::loadString("gravity_W = [1, 2]\n", "w.toml", c).message(),
              "w.toml:1:1: 'gravity_W': expected an array of 3 floats, got 2 elements (unit: "
              "m/s^2)");
    EXPECT_EQ(config::loadString("tags = [1]\n", "w.toml", c).message(),
              "w.toml:1:1: 'tags': element 0 of the array: expected a string, got an integer");
    EXPECT_EQ(config::loadString("[grid]\nblock_budget = -1\n", "w.toml", c).message(),
              "w.toml:2:1: 'grid.block_budget': expected a non-negative integer, got -1 (unit: "
              "blocks)");
    EXPECT_EQ(c, TestConfig{});
}

TEST(Config, OutOfRangeValuesAreErrors) {
    TestConfig c;
    EXPECT_EQ(config::loadString("[grid.volume]\nvoxel_size_m = 0\n", "r.toml", c).message(),
              "r.toml:2:1: 'grid.volume.voxel_size_m' = 0.0 is out of range (0, 1] m");
    EXPECT_EQ(config::loadString("[grid.volume]\ntruncation_voxels = 17\n", "r.toml", c).message(),
              "r.toml:2:1: 'grid.volume.truncation_voxels' = 17 is out of range [1, 16] voxels");
    EXPECT_EQ(config::loadString("tint = [0.5, 1.5, 0]\n", "r.toml", c).message(),
              "r.toml:1:1: 'tint' = [0.5, 1.5, 0.0] is out of range [0, 1]");
    EXPECT_EQ(config::loadString("epsilon = nan\n", "r.toml", c).message(),
              "r.toml:1:1: 'epsilon' = nan is out of range > 0");
    // Boundaries: inclusive bounds accept the limit.
    EXPECT_TRUE(
        config::loadString("[grid.volume]\nvoxel_size_m = 1\ntruncation_voxels = 16\n", "r.toml", c)
            .isOk());
    EXPECT_EQ(c.grid.volume.voxel_size_m, 1.0);
    EXPECT_EQ(c.grid.volume.truncation_voxels, 16);
}

TEST(Config, SyntaxErrorsCarryFileLineColumn) {
    TestConfig c;
    const Status st = config::loadString("seed = 1\nname = \"unterminated\n", "s.toml", c);
    ASSERT_FALSE(st.isOk());
    EXPECT_EQ(st.message().rfind("s.toml:2:", 0), 0u) << st.message();
    EXPECT_NE(st.message().find("TOML syntax error"), std::string::npos) << st.message();
    const Status missing = config::loadFile("/nonexistent/plumb.toml", c);
    EXPECT_EQ(missing.code(), StatusCode::kNotFound);
    EXPECT_EQ(missing.message(), "/nonexistent/plumb.toml: configuration file does not exist");
}

TEST(Config, CommandLineOverridesUseTheSameValidation) {
    TestConfig c;
    ASSERT_TRUE(config::applyOverrides(
                    {"grid.volume.voxel_size_m=0.02", "mode=accurate", "name=plain text",
                     "tags=[\"x\", \"y\"]", "verbose = true", "gravity_W=[1,2,3]", "name2=1"},
                    c)
                    .isOk() == false);
    EXPECT_EQ(c, TestConfig{});  // the bad last assignment left everything unchanged

    ASSERT_TRUE(config::applyOverrides({"grid.volume.voxel_size_m=0.02", "mode=accurate",
                                        "name=plain text", "tags=[\"x\", \"y\"]", "verbose = true",
                                        "gravity_W=[1,2,3]", "grid.block_budget=7"},
                                       c)
                    .isOk());
    EXPECT_EQ(c.grid.volume.voxel_size_m, 0.02);
    EXPECT_EQ(c.mode, Mode::kAccurate);
    EXPECT_EQ(c.name, "plain text");
    EXPECT_EQ(c.tags, (std::vector<std::string>{"x", "y"}));
    EXPECT_TRUE(c.verbose);
    EXPECT_EQ(c.gravity_W, Eigen::Vector3d(1, 2, 3));
    EXPECT_EQ(c.grid.block_budget, 7u);

    const TestConfig before = c;
    auto error = [&](const std::string& a) { return config::applyOverrides({a}, c).message(); };
    EXPECT_EQ(error("grid.volume.voxel_sizem=0.01"),
              "--set grid.volume.voxel_sizem=0.01: unknown key 'grid.volume.voxel_sizem' (did you "
              "mean 'grid.volume.voxel_size_m'?)");
    EXPECT_EQ(error("grd.block_budget=1"),
              "--set grd.block_budget=1: unknown key 'grd.block_budget' (did you mean 'grid'?)");
    EXPECT_EQ(error("grid.volume.voxel_size_m=abc"),
              "--set grid.volume.voxel_size_m=abc: 'abc' is not a valid float value");
    EXPECT_EQ(error("grid.volume.voxel_size_m=2"),
              "--set grid.volume.voxel_size_m=2: 'grid.volume.voxel_size_m' = 2.0 is out of range "
              "(0, 1] m");
    EXPECT_EQ(error("seed=\"x\""), "--set seed=\"x\": 'seed': expected an integer, got a string");
    EXPECT_EQ(error("mode=slow"),
              "--set mode=slow: 'mode': expected one of fast, accurate, got 'slow'");
    EXPECT_EQ(error("grid=1"),
              "--set grid=1: 'grid' is a section; set one of its keys (grid.<key>=value)");
    EXPECT_EQ(error("seed.x=1"), "--set seed.x=1: 'seed' is a key, not a section");
    EXPECT_EQ(error("seed"), "--set seed: expected section.key=value");
    EXPECT_EQ(c, before);
}

TEST(Config, ExtractsConfigFlagsFromArguments) {
    std::vector<std::string> args = {"in.dir", "--config", "a.toml",         "--set",
                                     "seed=1", "-v",       "--set=mode=fast"};
    const Result<config::ConfigArgs> r = config::extractConfigArgs(args);
    ASSERT_TRUE(r.isOk()) << r.status().toString();
    EXPECT_EQ(r->file, "a.toml");
    EXPECT_EQ(r->overrides, (std::vector<std::string>{"seed=1", "mode=fast"}));
    EXPECT_EQ(args, (std::vector<std::string>{"in.dir", "-v"}));
    std::vector<std::string> bad = {"--set"};
    EXPECT_EQ(config::extractConfigArgs(bad).status().message(), "--set needs a value");
    std::vector<std::string> twice = {"--config=a", "--config", "b"};
    EXPECT_EQ(config::extractConfigArgs(twice).status().message(), "--config given twice");
}

TEST(Config, LoadAppliesFileThenOverridesThenValidates) {
    const auto dir = testing::freshTempDir("config_load");
    {
        std::ofstream out(dir / "c.toml");
        out << "seed = 5\n[grid.volume]\nvoxel_size_m = 0.03\n";
    }
    TestConfig c;
    ASSERT_TRUE(config::load({dir / "c.toml", {"grid.volume.voxel_size_m=0.05"}}, c).isOk());
    EXPECT_EQ(c.seed, 5);
    EXPECT_EQ(c.grid.volume.voxel_size_m, 0.05);  // the flag wins over the file
    // A value set in code outside its bounds is caught by validation.
    TestConfig broken;
    broken.grid.volume.truncation_voxels = 0;
    broken.mode = static_cast<Mode>(7);
    EXPECT_EQ(config::validate(broken).message(),
              "'mode' = \"<unnamed value 7>\" is invalid (expected one of: fast, accurate)\n"
              "'grid.volume.truncation_voxels' = 0 is out of range [1, 16] voxels");
    EXPECT_FALSE(config::load({}, broken).isOk());
    EXPECT_TRUE(config::validate(TestConfig{}).isOk());
}

TEST(Config, WrittenTomlRoundTripsExactly) {
    TestConfig c;
    c.name = "quote \" backslash \\ newline \n tab \t bell \x07 unicode \xc3\xa9";
    c.seed = std::numeric_limits<int64_t>::min();
    c.mode = Mode::kAccurate;
    c.gravity_W = Eigen::Vector3d(0.1, -1e-300, 1.0 / 3.0);
    c.tint = Eigen::Vector3f(1.0f / 3.0f, 0.0f, 1.0f);
    c.level_weights = {std::numeric_limits<double>::infinity(), 0.0, 123456789.123456789, 5e-324};
    c.skip_frames = {0, std::numeric_limits<int64_t>::max()};
    c.tags = {};
    c.epsilon = std::numeric_limits<float>::denorm_min();
    c.grid.block_budget = 12345678901ull;
    c.grid.volume.voxel_size_m = 0.1 + 0.2;  // 0.30000000000000004
    c.grid.volume.max_weight = 16777217.0f;  // rounds to 16777216 as a float
    const std::string text = config::toToml(c, "test configuration");
    TestConfig back;
    const Status st = config::loadString(text, "written.toml", back);
    ASSERT_TRUE(st.isOk()) << st.toString() << "\n" << text;
    EXPECT_EQ(back, c) << text;

    // Every float value round-trips too: a sweep over awkward values.
    for (float f : {0.1f, 0.7f, 1e-38f, 3.4028235e38f, 1.17549435e-38f, 9.999999e-4f, 123.456f}) {
        TestConfig a;
        a.epsilon = f;
        TestConfig b;
        ASSERT_TRUE(config::loadString(config::toToml(a), "f.toml", b).isOk()) << f;
        EXPECT_EQ(b.epsilon, f);
    }
    // And defaults round-trip.
    TestConfig d;
    ASSERT_TRUE(config::loadString(config::toToml(TestConfig{}), "d.toml", d).isOk());
    EXPECT_EQ(d, TestConfig{});
}

TEST(Config, WrittenTomlDocumentsEveryKey) {
    TestConfig c;
    c.grid.volume.voxel_size_m = 0.02;
    const std::string text = config::toToml(c, "plumb test");
    EXPECT_EQ(text.rfind("# plumb test\n", 0), 0u);
    EXPECT_NE(text.find("# TSDF voxel edge length.\n"
                        "# Type: float. Unit: m. Range: (0, 1]. Default: 0.01.\n"
                        "voxel_size_m = 0.02\n"),
              std::string::npos)
        << text;
    EXPECT_NE(text.find("# voxel grid\n[grid]\n"), std::string::npos) << text;
    EXPECT_NE(text.find("# the fused volume\n[grid.volume]\n"), std::string::npos) << text;
    EXPECT_NE(text.find("# Type: one of: fast, accurate. Default: \"fast\".\nmode = \"fast\"\n"),
              std::string::npos)
        << text;
    // Every key appears as an assignment exactly once.
    TestConfig bound;
    const config::Schema s = config::bind(bound);
    ASSERT_EQ(s.keys().size(), 14u);
    for (const std::string& key : s.keys()) {
        const std::string leaf =
            key.substr(key.rfind('.') == std::string::npos ? 0 : key.rfind('.') + 1);
        size_t count = 0;
        for (size_t at = text.find("\n" + leaf + " = "); at != std::string::npos;
             at = text.find("\n" + leaf + " = ", at + 1)) {
            ++count;
        }
        EXPECT_EQ(count, 1u) << key;
    }
}

TEST(Config, MarkdownTableListsKeyTypeDefaultUnitMeaning) {
    const std::string md = config::toMarkdown<TestConfig>();
    EXPECT_EQ(md.rfind("| key | type | default | unit | meaning |\n|---|---|---|---|---|\n", 0),
              0u);
    EXPECT_NE(md.find("| `grid.volume.voxel_size_m` | float | `0.01` | m | TSDF voxel edge length "
                      "(range (0, 1]) |\n"),
              std::string::npos)
        << md;
    EXPECT_NE(md.find("| `mode` | one of: fast, accurate | `\"fast\"` |  | speed/accuracy "
                      "trade-off |\n"),
              std::string::npos)
        << md;
    EXPECT_NE(md.find("| `gravity_W` | array of 3 floats | `[0.0, 0.0, -9.81]` | m/s^2 |"),
              std::string::npos)
        << md;
    // One header, one separator and one row per key.
    EXPECT_EQ(static_cast<size_t>(std::count(md.begin(), md.end(), '\n')), 2u + 14u);
}

TEST(Config, EditDistanceCountsSingleEdits) {
    EXPECT_EQ(config::editDistance("voxel_size_m", "voxel_size_m"), 0u);
    EXPECT_EQ(config::editDistance("voxel_sise_m", "voxel_size_m"), 1u);  // substitution
    EXPECT_EQ(config::editDistance("voxel_size", "voxel_size_m"), 2u);    // two insertions
    EXPECT_EQ(config::editDistance("vxoel_size_m", "voxel_size_m"), 1u);  // transposition
    EXPECT_EQ(config::editDistance("Voxel_Size_M", "voxel_size_m"), 0u);  // case ignored
    EXPECT_EQ(config::editDistance("", "abc"), 3u);
}

TEST(ConfigRegistry, RegisteredProgramConfigDocumentsAndChecks) {
    ASSERT_TRUE(config::registerProgramConfig<TestConfig>("test-program", "a test program"));
    EXPECT_FALSE(config::registerProgramConfig<TestConfig>("test-program", "twice"));
    const Result<config::ProgramConfig> p = config::findProgramConfig("test-program");
    ASSERT_TRUE(p.isOk());
    EXPECT_EQ(p->summary, "a test program");
    EXPECT_EQ(p->markdown(), config::toMarkdown<TestConfig>());
    EXPECT_EQ(p->defaults_toml().rfind("# plumb test-program configuration (defaults)\n", 0), 0u);
    const Result<std::string> effective = p->check({{}, {"seed=9"}});
    ASSERT_TRUE(effective.isOk());
    TestConfig back;
    ASSERT_TRUE(config::loadString(*effective, "e.toml", back).isOk());
    EXPECT_EQ(back.seed, 9);
    EXPECT_EQ(p->check({{}, {"sed=9"}}).status().message(),
              "--set sed=9: unknown key 'sed' (did you mean 'seed'?)");
    EXPECT_EQ(config::findProgramConfig("nope").status().message(),
              "no configuration schema named 'nope' (registered: test-program)");
}

}  // namespace
}  // namespace plumb
