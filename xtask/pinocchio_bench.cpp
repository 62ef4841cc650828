// Pinocchio's pipeline for a leg, timed: the benchmarks' second peer (`cargo xtask bench
// --pinocchio` builds and runs it; it is not part of CI). The model is built with
// Pinocchio's API from the leg file that xtask writes from the spec (revolute joints about
// z, the spec's masses, centres of mass, inertias and reflected rotor inertia as armature,
// closure frames `<closure>_a` / `<closure>_b`).
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

namespace pin = pinocchio;

template <int N, int NC>
int run(pin::Model& model, const std::vector<std::string>& closures, const Eigen::VectorXd& damping,
        const Eigen::VectorXd& q0, const Eigen::VectorXd& v0) {
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
  std::printf("{\"M\": [");
  for (int r = 0; r < N; ++r) {
    std::printf("%s[", r ? ", " : "");
    for (int c = 0; c < N; ++c) std::printf("%s%.17g", c ? ", " : "", data.M(r, c));
    std::printf("]");
  }
  std::printf("], \"N\": [");
  for (int r = 0; r < N; ++r) std::printf("%s%.17g", r ? ", " : "", data.nle(r));
  std::printf("], \"qdd\": [");
  for (int r = 0; r < N; ++r) std::printf("%s%.17g", r ? ", " : "", sol(r));
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
  // The leg file, written by `cargo xtask bench --pinocchio` from the spec:
  //   gravity GX GY
  //   link NAME PARENT OX OY MASS CX CY INERTIA ARMATURE DAMPING   (PARENT: -1 for the base)
  //   closure NAME LINK_A AX AY LINK_B BX BY
  //   state Q... QD...
  std::FILE* f = std::fopen(argv[1], "r");
  if (!f) {
    std::fprintf(stderr, "cannot read %s\n", argv[1]);
    return 1;
  }
  pin::Model model;
  std::vector<pin::JointIndex> joints;
  std::vector<std::string> closures;
  std::vector<double> armature, damping, state;
  char kind[32], name[128];
  while (std::fscanf(f, "%31s", kind) == 1) {
    const std::string k = kind;
    if (k == "gravity") {
      double gx, gy;
      if (std::fscanf(f, "%lf %lf", &gx, &gy) != 2) return 1;
      model.gravity.linear(Eigen::Vector3d(gx, gy, 0.0));
    } else if (k == "link") {
      int parent;
      double ox, oy, m, cx, cy, inertia, arm, d;
      if (std::fscanf(f, "%127s %d %lf %lf %lf %lf %lf %lf %lf %lf", name, &parent, &ox, &oy, &m, &cx, &cy, &inertia, &arm, &d) != 10) return 1;
      const pin::JointIndex p = parent < 0 ? 0 : joints[parent];
      const pin::JointIndex j = model.addJoint(p, pin::JointModelRZ(), pin::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(ox, oy, 0)), name);
      model.appendBodyToJoint(j, pin::Inertia(m, Eigen::Vector3d(cx, cy, 0), Eigen::Vector3d(inertia, inertia, inertia).asDiagonal()), pin::SE3::Identity());
      joints.push_back(j);
      armature.push_back(arm);
      damping.push_back(d);
    } else if (k == "closure") {
      int la, lb;
      double ax, ay, bx, by;
      if (std::fscanf(f, "%127s %d %lf %lf %d %lf %lf", name, &la, &ax, &ay, &lb, &bx, &by) != 7) return 1;
      const std::string n = name;
      model.addFrame(pin::Frame(n + "_a", joints[la], pin::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(ax, ay, 0)), pin::OP_FRAME));
      model.addFrame(pin::Frame(n + "_b", joints[lb], pin::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(bx, by, 0)), pin::OP_FRAME));
      closures.push_back(n);
    } else if (k == "state") {
      double x;
      for (std::size_t i = 0; i < 2 * joints.size(); ++i) {
        if (std::fscanf(f, "%lf", &x) != 1) return 1;
        state.push_back(x);
      }
    } else {
      std::fprintf(stderr, "unknown line `%s`\n", kind);
      return 1;
    }
  }
  std::fclose(f);
  const int nq = int(joints.size());
  for (int i = 0; i < nq; ++i) model.armature(i) = armature[i];
  const Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(state.data(), nq);
  const Eigen::VectorXd v = Eigen::Map<const Eigen::VectorXd>(state.data() + nq, nq);
  const Eigen::VectorXd d = Eigen::Map<const Eigen::VectorXd>(damping.data(), nq);
  const int nc = 2 * int(closures.size());
  // Fixed-size instances for the legs' sizes (a closure with redundant rows has a singular
  // KKT matrix, which the LU here does not handle: those legs have no instance).
  if (nq == 4 && nc == 2) return run<4, 2>(model, closures, d, q, v);
  if (nq == 2 && nc == 0) return run<2, 0>(model, closures, d, q, v);
  if (nq == 3 && nc == 0) return run<3, 0>(model, closures, d, q, v);
  std::fprintf(stderr, "no fixed-size instance for NQ = %d, NC = %d\n", nq, nc);
  return 1;
}
