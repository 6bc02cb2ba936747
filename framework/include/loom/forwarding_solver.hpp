// A LinearSolver that passes every call to another one: derive from it and override only what
// a wrapper changes (a record of the solves, a timer, a hidden capability).
#pragma once

#include <memory>
#include <span>
#include <string>
#include <utility>

#include "loom/linear_solver.hpp"

namespace loom {

class ForwardingSolver : public LinearSolver {
 public:
  explicit ForwardingSolver(std::unique_ptr<LinearSolver> inner) : inner_(std::move(inner)) {}
  std::string name() const override { return inner_->name(); }
  void analyze_pattern(const BsrMatrix& A, const Filter& S) override { inner_->analyze_pattern(A, S); }
  bool factorize(const BsrMatrix& A, const Filter& S, SolveReport& report) override {
    return inner_->factorize(A, S, report);
  }
  SolveReport solve(const BsrMatrix& A, const Filter& S, std::span<const double> b, std::span<const double> z,
                    std::span<double> dv) override {
    return inner_->solve(A, S, b, z, dv);
  }
  void set_coordinates(std::span<const double> x) override { inner_->set_coordinates(x); }
  bool supports_extra_operator() const override { return inner_->supports_extra_operator(); }
  void set_extra_operator(const ExtraOperator* E) override { inner_->set_extra_operator(E); }
  bool set_tolerance_scale(double s) override { return inner_->set_tolerance_scale(s); }

 private:
  std::unique_ptr<LinearSolver> inner_;
};

}  // namespace loom
