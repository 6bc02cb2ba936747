// A CSV file of Loom's output (stats.csv, study.csv, stability.csv) as read by the tests: the
// header, then the fields of every row (double quotes group a field that holds commas).
#pragma once

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace loom_test {

struct CsvTable {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;

  /// The rows as column name -> field (fields beyond the header are dropped: check rows' sizes first).
  std::vector<std::map<std::string, std::string>> by_name() const {
    std::vector<std::map<std::string, std::string>> out;
    for (const auto& r : rows) {
      std::map<std::string, std::string> m;
      for (std::size_t k = 0; k < r.size() && k < header.size(); ++k) m[header[k]] = r[k];
      out.push_back(std::move(m));
    }
    return out;
  }
};

inline std::vector<std::string> csv_fields(const std::string& line) {
  std::vector<std::string> f;
  std::string cur;
  bool quoted = false;
  for (char c : line) {
    if (c == '"') quoted = !quoted;
    else if (c == ',' && !quoted) f.push_back(cur), cur.clear();
    else cur += c;
  }
  f.push_back(cur);
  return f;
}

inline CsvTable read_csv_table(const std::filesystem::path& p) {
  CsvTable t;
  std::ifstream in(p);
  std::string line;
  if (std::getline(in, line)) t.header = csv_fields(line);
  while (std::getline(in, line)) t.rows.push_back(csv_fields(line));
  return t;
}

}  // namespace loom_test
