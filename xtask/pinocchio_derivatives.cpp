// Pinocchio's constrained-dynamics derivatives for a planar closed-chain leg, timed: a peer
// for the project's `forward_dynamics_derivatives` (legs eval --derivatives).
//
// usage: pinocchio_derivatives LEG_FILE ACTUATED U [--frame local|lwa] [--mu MU]
//                              [--max-iter N] [--accuracy EPS] [--swap] [--fd] [--no-fix]
//   LEG_FILE  the leg file (pinocchio_leg.hpp), whose `state` line is the state (q, q̇)
//   ACTUATED  the actuated joints' indices in the spec's order, comma separated ("0,2")
//   U         the motor torques, comma separated ("0.05,0.1"); B has one 1 per motor
//   --swap    each closure's joint1 is point b's joint (default: point a's)
//   --fd      also print fd_dqdd_dq: central differences of constraintDynamics' q̈
//   --no-fix  keep Pinocchio 4.1's loop_span_indexes as constructed (see the fix below)
//
// Each closure `<c>_a` / `<c>_b` is one RigidConstraintModel CONTACT_3D between the two
// frames' joints (or one joint and the universe) at the frames' placements, no Baumgarte
// correction. A planar mechanism leaves the z row of each contact identically zero, so the
// Delassus matrix J M⁻¹ Jᵀ is singular: Pinocchio's proximal settings (mu > 0) regularize
// it, and the proximal iterations (settings.iter, which the derivatives reuse) converge on
// its range.
//
// tau = B u − D q̇ (viscous damping as a joint torque, as in pinocchio_bench.cpp), so
//   ∂q̈/∂q̇ = ddq_dv − ddq_dtau D,   ∂q̈/∂u = ddq_dtau B,
// and likewise for λ. λ's x, y rows are the closure force F (on point a, world axes; with
// --frame local, λ is rotated to world axes and its derivatives get the rotation's term).
//
// One call = constraintDynamics + computeConstraintDynamicsDerivatives (+ the two products
// above), inputs prepared once, q(0) moved by 1e-9 every call. Prints one JSON object, rows
// and columns in the spec's joint order, and the median time of one call in ns.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <pinocchio/multibody.hpp>
#include <pinocchio/constraints.hpp>
#include <pinocchio/algorithm/constrained-dynamics.hpp>
#include <pinocchio/algorithm/constrained-dynamics-derivatives.hpp>

#include "pinocchio_leg.hpp"

namespace pin = pinocchio;

static std::vector<double> parse_list(const char* s) {
  std::vector<double> out;
  std::string t(s);
  std::size_t p = 0;
  while (p <= t.size() && !t.empty()) {
    std::size_t e = t.find(',', p);
    if (e == std::string::npos) e = t.size();
    out.push_back(std::atof(t.substr(p, e - p).c_str()));
    p = e + 1;
  }
  return out;
}

// Rows `rows` (already in the output's order) and columns in the spec's order.
static void print_matrix(const char* key, const Eigen::MatrixXd& m, const std::vector<int>& rows,
                         const std::vector<int>& cols) {
  std::printf(", \"%s\": [", key);
  for (std::size_t r = 0; r < rows.size(); ++r) {
    std::printf("%s[", r ? ", " : "");
    for (std::size_t c = 0; c < cols.size(); ++c) std::printf("%s%.17g", c ? ", " : "", m(rows[r], cols[c]));
    std::printf("]");
  }
  std::printf("]");
}

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr,
                 "usage: pinocchio_derivatives LEG_FILE ACTUATED U [--frame local|lwa] [--mu MU] "
                 "[--max-iter N] [--accuracy EPS] [--swap] [--fd] [--no-fix]\n");
    return 2;
  }
  pin::ReferenceFrame frame = pin::LOCAL_WORLD_ALIGNED;
  double mu = 1e-8, accuracy = 1e-14;
  int max_iter = 20;
  bool swap_all = false, fd = false, fix = true;
  for (int i = 4; i < argc; i += 2) {
    if (!std::strcmp(argv[i], "--no-fix")) {
      fix = false;
      --i;
    } else if (!std::strcmp(argv[i], "--swap")) {
      swap_all = true;
      --i;
    } else if (!std::strcmp(argv[i], "--fd")) {
      fd = true;
      --i;
    } else if (i + 1 >= argc) {
      std::fprintf(stderr, "%s needs a value\n", argv[i]);
      return 2;
    } else if (!std::strcmp(argv[i], "--frame"))
      frame = std::strcmp(argv[i + 1], "local") ? pin::LOCAL_WORLD_ALIGNED : pin::LOCAL;
    else if (!std::strcmp(argv[i], "--mu"))
      mu = std::atof(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--max-iter"))
      max_iter = std::atoi(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--accuracy"))
      accuracy = std::atof(argv[i + 1]);
    else {
      std::fprintf(stderr, "unknown option %s\n", argv[i]);
      return 2;
    }
  }
  Leg leg;
  if (!read_leg(argv[1], leg)) return 1;
  pin::Model& model = leg.model;
  const int nv = model.nv;
  const std::vector<double> act = parse_list(argv[2]), u = parse_list(argv[3]);
  if (act.size() != u.size()) {
    std::fprintf(stderr, "ACTUATED and U differ in length\n");
    return 2;
  }
  // B in Pinocchio's joint order: column k is motor k's unit torque.
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(nv, int(u.size()));
  Eigen::VectorXd uv(int(u.size()));
  for (std::size_t k = 0; k < u.size(); ++k) {
    const int i = int(act[k]);
    if (i < 0 || i >= nv) {
      std::fprintf(stderr, "actuated joint %d out of range\n", i);
      return 2;
    }
    B(leg.at[i], int(k)) = 1.0;
    uv(int(k)) = u[k];
  }

  // The closures as 3D point contacts. A point on the base goes second (joint2 = universe);
  // if it is point a, the constraint is b − a and λ's sign flips.
  std::vector<pin::RigidConstraintModel> cmodels;
  std::vector<double> sign;
  for (const std::string& c : leg.closures) {
    const pin::Frame& fa = model.frames[model.getFrameId(c + "_a")];
    const pin::Frame& fb = model.frames[model.getFrameId(c + "_b")];
    if (fa.parentJoint == 0 && fb.parentJoint == 0) {
      std::fprintf(stderr, "closure %s: both points on the base\n", c.c_str());
      return 1;
    }
    // --swap: point b's joint first (joint1), unless b is on the base.
    const bool swap = fa.parentJoint == 0 || (swap_all && fb.parentJoint != 0);
    const pin::Frame& f1 = swap ? fb : fa;
    const pin::Frame& f2 = swap ? fa : fb;
    cmodels.emplace_back(pin::CONTACT_3D, model, f1.parentJoint, f1.placement, f2.parentJoint, f2.placement,
                         frame);
    cmodels.back().name = c;
    if (fix) {
      // Pinocchio 4.1 bug: RigidConstraintModelTpl's constructor initializes
      // loop_span_indexes((size_t)model.nv) (nv zeros) and init() then push_backs the real
      // columns, so the closed-loop term of computeConstraintDynamicsDerivatives visits
      // column 0 nv extra times (ddq_dq and dlambda_dq wrong in column 0 only). Rebuilt here
      // with init()'s own rule: the columns in exactly one of the two joints' supports.
      pin::RigidConstraintModel& cm = cmodels.back();
      const auto& s1 = model.sparsity_pattern_vector[cm.joint1_id];
      const auto& s2 = model.sparsity_pattern_vector[cm.joint2_id];
      cm.loop_span_indexes.clear();
      for (Eigen::Index col = 0; col < model.nv; ++col)
        if (s1[col] != s2[col]) cm.loop_span_indexes.push_back(col);
    }
    sign.push_back(swap ? -1.0 : 1.0);
  }
  std::vector<pin::RigidConstraintData> cdatas;
  for (const auto& cm : cmodels) cdatas.emplace_back(cm);
  pin::Data data(model);
  pin::initConstraintDynamics(model, data, cmodels, cdatas);
  pin::ProximalSettings settings(accuracy, mu, max_iter);
  const int nc = 3 * int(cmodels.size());

  const Eigen::VectorXd q0 = leg.q, v0 = leg.v;
  const Eigen::VectorXd tau = B * uv - leg.damping.cwiseProduct(v0);
  Eigen::MatrixXd ddq_dv_total(nv, nv), ddq_du(nv, int(u.size()));

  auto call = [&](const Eigen::VectorXd& q) {
    pin::constraintDynamics(model, data, q, v0, tau, cmodels, cdatas, settings);
    pin::computeConstraintDynamicsDerivatives(model, data, cmodels, cdatas, settings);
    ddq_dv_total.noalias() = data.ddq_dv - data.ddq_dtau * leg.damping.asDiagonal();
    ddq_du.noalias() = data.ddq_dtau * B;
  };

  call(q0);
  const int iters = settings.iter;
  const double abs_res = settings.absolute_residual, rel_res = settings.relative_residual;

  // λ's x, y rows as F in world axes, and their derivatives.
  Eigen::VectorXd F(2 * cmodels.size());
  Eigen::MatrixXd dF_dq(2 * cmodels.size(), nv), dF_dv(2 * cmodels.size(), nv),
      dF_du(2 * cmodels.size(), int(u.size()));
  const Eigen::MatrixXd dl_dv_total = data.dlambda_dv - data.dlambda_dtau * leg.damping.asDiagonal();
  const Eigen::MatrixXd dl_du = data.dlambda_dtau * B;
  double max_z = 0;
  for (std::size_t k = 0; k < cmodels.size(); ++k) {
    const int r = 3 * int(k);
    max_z = std::max(max_z, std::abs(data.lambda_c(r + 2)));
    Eigen::Matrix2d R = Eigen::Matrix2d::Identity();
    if (frame == pin::LOCAL) R = cdatas[k].oMc1.rotation().topLeftCorner<2, 2>();
    const Eigen::Vector2d f = sign[k] * R * data.lambda_c.segment<2>(r);
    F.segment<2>(2 * k) = f;
    dF_dq.middleRows<2>(2 * k) = sign[k] * R * data.dlambda_dq.middleRows<2>(r);
    dF_dv.middleRows<2>(2 * k) = sign[k] * R * dl_dv_total.middleRows<2>(r);
    dF_du.middleRows<2>(2 * k) = sign[k] * R * dl_du.middleRows<2>(r);
    if (frame == pin::LOCAL) {
      // R = Rz(sum of the angles of joint1's supporting joints): ∂(R λ)/∂q_j adds ẑ × (R λ).
      for (pin::JointIndex j : model.supports[cmodels[k].joint1_id])
        if (j > 0) {
          const int c = model.joints[j].idx_v();
          dF_dq(2 * k, c) += -f(1);
          dF_dq(2 * k + 1, c) += f(0);
        }
    }
  }

  // Spec order.
  std::vector<int> spec(nv), frows(F.size()), ucols(u.size());
  for (int i = 0; i < nv; ++i) spec[i] = leg.at[i];
  for (int i = 0; i < int(F.size()); ++i) frows[i] = i;
  for (int i = 0; i < int(u.size()); ++i) ucols[i] = i;
  std::printf("{\"loop_span_fix\": %s, \"frame\": \"%s\", \"mu\": %.3g, \"max_iter\": %d, \"accuracy\": %.3g, \"iter\": %d, "
              "\"absolute_residual\": %.3g, \"relative_residual\": %.3g, \"max_abs_lambda_z\": %.3g",
              fix ? "true" : "false", frame == pin::LOCAL ? "LOCAL" : "LOCAL_WORLD_ALIGNED", mu, max_iter, accuracy, iters, abs_res,
              rel_res, max_z);
  std::printf(", \"q\": [");
  for (int i = 0; i < nv; ++i) std::printf("%s%.17g", i ? ", " : "", q0(spec[i]));
  std::printf("], \"qd\": [");
  for (int i = 0; i < nv; ++i) std::printf("%s%.17g", i ? ", " : "", v0(spec[i]));
  std::printf("], \"qdd\": [");
  for (int i = 0; i < nv; ++i) std::printf("%s%.17g", i ? ", " : "", data.ddq(spec[i]));
  std::printf("], \"F\": [");
  for (int i = 0; i < int(F.size()); ++i) std::printf("%s%.17g", i ? ", " : "", F(i));
  std::printf("]");
  print_matrix("dqdd_dq", data.ddq_dq, spec, spec);
  print_matrix("dqdd_dqd", ddq_dv_total, spec, spec);
  print_matrix("dqdd_du", ddq_du, spec, ucols);
  print_matrix("dF_dq", dF_dq, frows, spec);
  print_matrix("dF_dqd", dF_dv, frows, spec);
  print_matrix("dF_du", dF_du, frows, ucols);
  (void)nc;
  if (fd) {
    // Central differences of constraintDynamics' q̈ (a check on ddq_dq, not timed).
    pin::ProximalSettings s2(accuracy, mu, max_iter);
    Eigen::MatrixXd fd_dq(nv, nv);
    const double h = 1e-6;
    for (int j = 0; j < nv; ++j) {
      Eigen::VectorXd qp = q0, qm = q0;
      qp(j) += h;
      qm(j) -= h;
      const Eigen::VectorXd ap = pin::constraintDynamics(model, data, qp, v0, tau, cmodels, cdatas, s2);
      const Eigen::VectorXd am = pin::constraintDynamics(model, data, qm, v0, tau, cmodels, cdatas, s2);
      fd_dq.col(j) = (ap - am) / (2 * h);
    }
    print_matrix("fd_dqdd_dq", fd_dq, spec, spec);
  }

  // Median over batches of the time of one call, on states that change every call.
  const int batch = 5000, batches = 15;
  std::vector<double> times;
  Eigen::VectorXd q = q0;
  double sink = 0;
  for (int b = 0; b < batches; ++b) {
    auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < batch; ++i) {
      q(0) = q0(0) + 1e-9 * i;
      call(q);
      sink += data.ddq_dq(0, 0) + ddq_dv_total(0, 0);
    }
    auto t1 = std::chrono::steady_clock::now();
    times.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count() / batch);
  }
  std::sort(times.begin(), times.end());
  std::printf(", \"median_ns\": %.3f, \"sink\": %.3g}\n", times[times.size() / 2], sink);
  return 0;
}
