#pragma once
/// Writes a law's step as linear expressions over [c (n states), w, x, r] and collects
/// them into a ControllerRealisation (controller/law.hpp).
#include "controller/law.hpp"

namespace twin::controller::laws {

using Row = Eigen::RowVectorXd;

class RealisationBuilder {
 public:
  explicit RealisationBuilder(int n) : n_(n), next_(n, n + 3) { next_.setZero(); }
  Row zero() const { return Row::Zero(n_ + 3); }
  Row state(int i) const { return unit(i); }
  Row w() const { return unit(n_); }
  Row x() const { return unit(n_ + 1); }
  Row r() const { return unit(n_ + 2); }
  void set_next(int i, const Row& e) { next_.row(i) = e; }
  ControllerRealisation finish(const Row& command, const Eigen::VectorXd& start, int reference_states) const {
    ControllerRealisation K;
    K.Ac = next_.leftCols(n_);
    K.By = next_.middleCols(n_, 2);
    K.Br = next_.col(n_ + 2);
    K.Cc = command.head(n_);
    K.Dy = command.segment(n_, 2);
    K.Dr = command(n_ + 2);
    K.start = start;
    K.reference_states = reference_states;
    return K;
  }

 private:
  Row unit(int i) const {
    Row e = zero();
    e(i) = 1.0;
    return e;
  }
  int n_;
  Eigen::MatrixXd next_;
};

}  // namespace twin::controller::laws
