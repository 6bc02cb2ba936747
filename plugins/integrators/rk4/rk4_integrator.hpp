// rk4: classical fourth-order Runge-Kutta over (x, v). Four force evaluations per step,
// forces divided by mass, pinned vertices follow their prescribed velocity at every stage.
#pragma once

#include <vector>

#include "loom/integrator.hpp"
#include "loom/params.hpp"

namespace loom {

class Rk4Integrator final : public Integrator {
 public:
  explicit Rk4Integrator(const Params& p = Params());
  std::string name() const override { return "rk4"; }
  void prepare(Scene& scene, double h) override;
  void step(Scene& scene, double h) override;
  StepStats last_step() const override { return stats_; }

 private:
  std::vector<double> xs_, vs_, f_, accx_, accv_;
  StepStats stats_;
};

}  // namespace loom
