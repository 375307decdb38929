// SPDX-License-Identifier: BSD-3-Clause
/**
 * @file cli.h
 * @brief skin3d_core (ROS-free): what every command-line tool checks before it reads any input: strict number
 * options and the results directory.
 *
 * The rule the tools follow (process_bag, dense_stereo, make_dataset, ...): a bad command line or an output
 * directory that cannot be written is refused at start, by name, before a single message is read, so that a long
 * run is never lost at its end.
 *
 * Exceptions and the exit codes process_bag documents:
 *  - common::CliError (a std::invalid_argument): a bad option value -> exit 2 (bad command line);
 *  - common::OutputError (a std::runtime_error): the output cannot be written -> exit 3.
 * Their what() is the whole message, ready to print after "TOOL: ".
 */
#pragma once

#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace skin3d {
namespace common {

/** @brief A bad option value; what() names the option and the value: "--frames: 'abc' is not a whole number >= 0". */
class CliError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

/** @brief The output directory cannot be made or written; what() names the path and the reason. */
class OutputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/**
 * @brief A whole number option, strictly: the whole of `text` is an optional sign and decimal digits (no spaces,
 * no trailing characters: "3x", " 3", "3.0", "" and "0x10" are refused), in [min, max].
 * @param option the option's name as the user typed it ("--frames"), put first in the message
 * @throws CliError "--frames: 'abc' is not a whole number >= 0" (the range as "between A and B", ">= A" or "<= B",
 *         whichever bounds are not the type's limits); out-of-range values of long give the same message.
 */
long parseWholeNumber(const std::string& option, const std::string& text, long min = 0,
                      long max = std::numeric_limits<long>::max());

/**
 * @brief A real number option, strictly: the whole of `text` is one finite decimal number (strtod syntax; "nan",
 * "inf", "", "1.5s", " 2" are refused), and it is > min (min_exclusive) or >= min, and <= max.
 * @throws CliError "--ate-max-dt: 'x' is not a number > 0".
 */
double parseNumber(const std::string& option, const std::string& text,
                   double min = -std::numeric_limits<double>::max(), bool min_exclusive = false,
                   double max = std::numeric_limits<double>::max());

/** @brief What prepareOutputDirectory did: the directory, and the directories it created (outermost first). */
struct PreparedOutput {
  std::string path;                  //!< the results directory, as given
  std::vector<std::string> created;  //!< the directories this call made, outermost first (empty: it existed)
  bool createdHere() const { return !created.empty(); }
};

/**
 * @brief Makes the results directory `path` ready before any processing: creates it and every missing parent
 * (as mkdir -p), then proves it writable by creating and removing a probe file in it.
 *
 * Call it right after parsing the command line, before opening the input, so that an unwritable or mistyped --out
 * is refused at once instead of after the whole bag. Nothing else is written; an existing directory and its
 * contents are left as they are.
 * @return the directory and the directories created here (for removeIfUnused on an early failure)
 * @throws OutputError "cannot write the results directory 'PATH': REASON" when `path` is empty, exists and is not
 *         a directory, a parent is a file, creating it fails, or the probe file cannot be written (read-only,
 *         no permission, full disk). Directories created before the failure are removed again.
 */
PreparedOutput prepareOutputDirectory(const std::string& path);

/**
 * @brief Undoes prepareOutputDirectory after a run that wrote nothing: removes the directories that call
 * created, innermost first, each only while it is empty. A directory that existed before, or that now holds
 * anything (results of the good frames, a log), is kept. Never throws.
 * @return true when the results directory itself was removed
 */
bool removeIfUnused(const PreparedOutput& prepared) noexcept;

/**
 * @brief removeIfUnused on scope exit unless keep() was called: put it in main() around the run, so that an early
 * failure (bad configuration, unreadable bag) leaves no empty results directory, while a run that wrote results
 * keeps them (removeIfUnused only removes empty directories, so keep() is an optimisation, not a requirement).
 */
class OutputDirectoryGuard {
 public:
  explicit OutputDirectoryGuard(PreparedOutput prepared) : prepared_(std::move(prepared)) {}
  OutputDirectoryGuard(const OutputDirectoryGuard&) = delete;
  OutputDirectoryGuard& operator=(const OutputDirectoryGuard&) = delete;
  ~OutputDirectoryGuard() {
    if (!keep_) removeIfUnused(prepared_);
  }
  void keep() { keep_ = true; }
  const PreparedOutput& prepared() const { return prepared_; }

 private:
  PreparedOutput prepared_;
  bool keep_ = false;
};

}  // namespace common
}  // namespace skin3d
