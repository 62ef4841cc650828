// Pinocchio's pipeline for a leg, timed: the benchmarks' second peer (`cargo xtask bench
// --pinocchio` builds and runs it; it is not part of CI). The model is built with
// Pinocchio's API from the leg file that xtask writes from the spec (pinocchio_leg.hpp).
//
// usage: pinocchio_bench LEG_FILE
//
// Per call: crba (mass matrix, armature on the diagonal), nonLinearEffects (C q̇ + G),
// forward kinematics with zero acceleration and the frame Jacobians and classical
// accelerations of the closure frames `<closure>_a` / `<closure>_b` (J and J̇ q̇), then the
// KKT system [M −Jᵀ; J 0] [q̈; F] = [−N; −J̇ q̇] solved with a fixed-size LU. Prints one JSON
// object: M, N, qdd (at the given state, for checking against the generated model) and
// the median time of one call in ns.
#include <algorithm>
#include <cmath>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include "pinocchio_leg.hpp"

namespace pin = pinocchio;

template <int N, int NC>
int run(pin::Model& model, const std::vector<std::string>& closures, const Eigen::VectorXd& damping,
        const Eigen::VectorXd& q0, const Eigen::VectorXd& v0, const std::vector<int>& at) {
  pin::Data data(model);
  std::vector<std::pair<pin::FrameIndex, pin::FrameIndex>> frames;
  for (const auto& c : closures) frames.emplace_back(model.getFrameId(c + "_a"), model.getFrameId(c + "_b"));
  Eigen::Matrix<double, 6, Eigen::Dynamic> ja(6, model.nv), jb(6, model.nv);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nv);
  Eigen::Matrix<double, N + NC, N + NC> kkt;
  Eigen::Matrix<double, N + NC, 1> rhs, sol;

  auto pipeline = [&](const Eigen::VectorXd& q, const Eigen::VectorXd& v) {
    pin::crba(model, data, q);
    data.M.triangularView<Eigen::StrictlyLower>() = data.M.transpose().triangularView<Eigen::StrictlyLower>();
    pin::nonLinearEffects(model, data, q, v);
    kkt.setZero();
    kkt.template topLeftCorner<N, N>() = data.M;
    // Viscous joint damping, which our forward dynamics includes (D q̇) and nle does not.
    rhs.template head<N>() = -data.nle - damping.cwiseProduct(v);
    if (NC > 0) {
      pin::forwardKinematics(model, data, q, v, zero);
      pin::computeJointJacobians(model, data, q);
      pin::updateFramePlacements(model, data);
      for (std::size_t k = 0; k < frames.size(); ++k) {
        ja.setZero();
        jb.setZero();
        pin::getFrameJacobian(model, data, frames[k].first, pin::LOCAL_WORLD_ALIGNED, ja);
        pin::getFrameJacobian(model, data, frames[k].second, pin::LOCAL_WORLD_ALIGNED, jb);
        const auto aa = pin::getFrameClassicalAcceleration(model, data, frames[k].first, pin::LOCAL_WORLD_ALIGNED);
        const auto ab = pin::getFrameClassicalAcceleration(model, data, frames[k].second, pin::LOCAL_WORLD_ALIGNED);
        for (int r = 0; r < 2; ++r) {
          const int row = N + 2 * int(k) + r;
          kkt.row(row).template head<N>() = ja.row(r) - jb.row(r);
          kkt.col(row).template head<N>() = -(ja.row(r) - jb.row(r)).transpose();
          rhs(row) = -(aa.linear()(r) - ab.linear()(r));
        }
      }
    }
    sol = kkt.partialPivLu().solve(rhs);
  };

  pipeline(q0, v0);
  // Printed in the spec's joint order (`at[i]`: where the spec's joint i is in Pinocchio's).
  std::printf("{\"M\": [");
  for (int r = 0; r < N; ++r) {
    std::printf("%s[", r ? ", " : "");
    for (int c = 0; c < N; ++c) std::printf("%s%.17g", c ? ", " : "", data.M(at[r], at[c]));
    std::printf("]");
  }
  std::printf("], \"N\": [");
  for (int r = 0; r < N; ++r) std::printf("%s%.17g", r ? ", " : "", data.nle(at[r]));
  std::printf("], \"qdd\": [");
  for (int r = 0; r < N; ++r) std::printf("%s%.17g", r ? ", " : "", sol(at[r]));
  std::printf("]");

  // Median over batches of the time of one call, on states that change every call.
  const int batch = 20000, batches = 15;
  std::vector<double> times;
  Eigen::VectorXd q = q0;
  double sink = 0;
  for (int b = 0; b < batches; ++b) {
    auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < batch; ++i) {
      q(0) = q0(0) + 1e-9 * i;
      pipeline(q, v0);
      sink += sol(0);
    }
    auto t1 = std::chrono::steady_clock::now();
    times.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count() / batch);
  }
  std::sort(times.begin(), times.end());
  std::printf(", \"median_ns\": %.3f, \"sink\": %.3g}\n", times[times.size() / 2], sink);
  return 0;
}

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: pinocchio_bench LEG_FILE\n");
    return 2;
  }
  Leg leg;
  if (!read_leg(argv[1], leg)) return 1;
  const int nq = leg.model.nq, nc = 2 * int(leg.closures.size());
#define INSTANCE(N, NC) \
  if (nq == N && nc == NC) return run<N, NC>(leg.model, leg.closures, leg.damping, leg.q, leg.v, leg.at);
  // Fixed-size instances for the legs' sizes (a closure with redundant rows has a singular
  // KKT matrix, which the LU here does not handle: those legs have no instance).
  INSTANCE(4, 2)
  INSTANCE(2, 0)
  INSTANCE(3, 0)
  INSTANCE(7, 4)
  INSTANCE(7, 6)
#undef INSTANCE
  std::fprintf(stderr, "no fixed-size instance for NQ = %d, NC = %d\n", nq, nc);
  return 1;
}
