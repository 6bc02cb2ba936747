// `loom plot RUN_DIR`, the study table and the stability-atlas plot. The plots are drawn by
// Python scripts (matplotlib) run as separate programs: nothing in the library plots.
#pragma once

#include <string>
#include <vector>

#include "loom/study.hpp"

namespace loom::cli {

/// Plot RUN_DIR/stats.csv to out_png (default RUN_DIR/stats.png) with scripts/plot_run.py.
/// Throws InputError naming the missing file or dependency and the fix.
int plot_command(const std::string& run_dir, const std::string& out_png, bool quiet);

/// Plot DIR/stability.csv to DIR/stability.png (scripts/plot_stability.py); without python3 +
/// matplotlib, a note says so (the CSV is the result; the plot is a convenience).
void plot_stability(const std::string& dir, bool quiet);

/// scripts/plot_study.py on DIR/study.csv -> DIR/study.png (a note when python3/matplotlib is missing).
void plot_study(const std::string& dir, bool quiet);

/// The study's results as a table on stdout, one row per combo, step and time.
void print_study_table(const std::vector<StudyRow>& rows);

/// The path of scripts/NAME: the source tree's, else the install tree's (share/loom/scripts).
std::string find_script(const std::string& name);

}  // namespace loom::cli
