// SPDX-License-Identifier: BSD-3-Clause
// The tools' command-line helpers (skin3d/common/cli.h): strict numbers and the results directory prepared before
// any processing.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include "skin3d/common/cli.h"

namespace fs = std::filesystem;
using skin3d::common::CliError;
using skin3d::common::OutputError;

namespace {
std::string messageOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

fs::path scratch(const std::string& name) {
  const fs::path p = fs::temp_directory_path() / ("skin3d_test_cli_" + std::to_string(::getpid())) / name;
  fs::remove_all(p);
  fs::create_directories(p.parent_path());
  return p;
}
}  // namespace

TEST(Cli, WholeNumbersAreStrictAndTheMessageNamesTheOption) {
  using skin3d::common::parseWholeNumber;
  EXPECT_EQ(parseWholeNumber("--frames", "3"), 3);
  EXPECT_EQ(parseWholeNumber("--frames", "0"), 0);
  EXPECT_EQ(parseWholeNumber("--frames", "+12"), 12);
  EXPECT_EQ(parseWholeNumber("--shift", "-5", -10, 10), -5);
  EXPECT_EQ(messageOf([] { parseWholeNumber("--frames", "abc"); }), "--frames: 'abc' is not a whole number >= 0");
  EXPECT_EQ(messageOf([] { parseWholeNumber("--frames", "-5"); }), "--frames: '-5' is not a whole number >= 0");
  EXPECT_EQ(messageOf([] { parseWholeNumber("--frames", "3x"); }), "--frames: '3x' is not a whole number >= 0");
  EXPECT_EQ(messageOf([] { parseWholeNumber("--n", "11", 1, 10); }), "--n: '11' is not a whole number >= 1 and <= 10");
  for (const char* bad : {"", " 3", "3 ", "3.0", "0x10", "1e3", "-", "+", "99999999999999999999999"})
    EXPECT_THROW(parseWholeNumber("--frames", bad), CliError) << "'" << bad << "'";
  EXPECT_THROW(parseWholeNumber("--frames", "abc"), std::invalid_argument);  // the exit-2 family
}

TEST(Cli, RealNumbersAreFiniteWholeTextsInRange) {
  using skin3d::common::parseNumber;
  EXPECT_DOUBLE_EQ(parseNumber("--x", "0.25"), 0.25);
  EXPECT_DOUBLE_EQ(parseNumber("--x", "-1e-3"), -1e-3);
  EXPECT_DOUBLE_EQ(parseNumber("--ate-max-dt", "0.01", 0.0, true), 0.01);
  EXPECT_EQ(messageOf([] { parseNumber("--ate-max-dt", "0", 0.0, true); }), "--ate-max-dt: '0' is not a number > 0");
  EXPECT_EQ(messageOf([] { parseNumber("--ate-max-dt", "x", 0.0, true); }), "--ate-max-dt: 'x' is not a number > 0");
  EXPECT_EQ(messageOf([] { parseNumber("--a", "2", 0.0, false, 1.0); }), "--a: '2' is not a number >= 0 and <= 1");
  for (const char* bad : {"", "nan", "inf", "-inf", "1.5s", " 2", "2 ", "1e999"})
    EXPECT_THROW(parseNumber("--x", bad), CliError) << "'" << bad << "'";
}

TEST(Cli, OutputDirectoryIsCreatedWithItsParentsAndRemovedWhenUnused) {
  using namespace skin3d::common;
  const fs::path base = scratch("make");
  const fs::path out = base / "a" / "b";
  const PreparedOutput p = prepareOutputDirectory(out.string());
  EXPECT_TRUE(fs::is_directory(out));
  EXPECT_TRUE(fs::is_empty(out)) << "the probe file is removed";
  ASSERT_EQ(p.created.size(), 3u);  // base, a, b: outermost first
  EXPECT_EQ(fs::path(p.created.front()), base);
  EXPECT_TRUE(p.createdHere());
  EXPECT_TRUE(removeIfUnused(p));
  EXPECT_FALSE(fs::exists(base)) << "every directory this run made is gone";

  // Something written: kept (and its parents).
  const PreparedOutput q = prepareOutputDirectory(out.string());
  std::ofstream(out / "trajectory.tum") << "1 0 0 0 0 0 0 1\n";
  EXPECT_FALSE(removeIfUnused(q));
  EXPECT_TRUE(fs::exists(out / "trajectory.tum"));

  // An existing directory is neither touched nor removed.
  const PreparedOutput r = prepareOutputDirectory(base.string());
  EXPECT_FALSE(r.createdHere());
  EXPECT_FALSE(removeIfUnused(r));
  EXPECT_TRUE(fs::exists(base));

  // The guard: removed on scope exit when empty.
  const fs::path g = base / "guarded";
  { OutputDirectoryGuard guard(prepareOutputDirectory(g.string())); }
  EXPECT_FALSE(fs::exists(g));
  {
    OutputDirectoryGuard guard(prepareOutputDirectory(g.string()));
    guard.keep();
  }
  EXPECT_TRUE(fs::exists(g));
  fs::remove_all(base.parent_path());
}

TEST(Cli, AnOutputDirectoryThatCannotBeWrittenIsRefusedByName) {
  using namespace skin3d::common;
  const fs::path base = scratch("refuse");
  fs::create_directories(base);
  const fs::path file = base / "plain_file";
  std::ofstream(file) << "x";
  // A parent that is a file (refused whoever runs the test, root included).
  const std::string under_file = (file / "out").string();
  const std::string m = messageOf([&] { prepareOutputDirectory(under_file); });
  EXPECT_NE(m.find("cannot write the results directory '" + under_file + "'"), std::string::npos) << m;
  EXPECT_NE(m.find("is not a directory"), std::string::npos) << m;
  EXPECT_THROW(prepareOutputDirectory(file.string()), OutputError);
  EXPECT_THROW(prepareOutputDirectory(""), std::runtime_error);  // the exit-3 family
  // A read-only directory (root writes anyway: then only that it does not throw something else).
  const fs::path ro = base / "read_only";
  fs::create_directories(ro);
  ::chmod(ro.c_str(), 0555);
  if (::geteuid() != 0) {
    EXPECT_THROW(prepareOutputDirectory((ro / "out").string()), OutputError);
    EXPECT_FALSE(fs::exists(ro / "out"));
  }
  ::chmod(ro.c_str(), 0755);
  fs::remove_all(base.parent_path());
}
