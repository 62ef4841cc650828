// Pinocchio's algorithms evaluated on casadi::SX and emitted as C by CasADi's code
// generator: what a CasADi + Pinocchio user runs (`cargo xtask bench --pinocchio` builds
// and runs it; it is not part of CI).
//
// usage: pinocchio_casadi LEG_FILE OUT_C
//
// The same pipeline as pinocchio_bench.cpp, on symbols: crba (mass matrix, armature on the
// diagonal), nonLinearEffects (C q̇ + G), frame Jacobians and classical accelerations of the
// closure frames (J and J̇ q̇), and the KKT system [M −Jᵀ; J 0] [q̈; F] = [τ − N − D q̇; −J̇ q̇]
// solved by CasADi's symbolic `solve`, as CasADi's own peers are. Two functions, in the
// spec's joint order, with common subexpressions eliminated:
//   pin_dynamics_terms(q, qd) -> (M, N, J, Jdot_qd)
//   pin_forward_dynamics(q, qd, tau) -> (qdd, F)
// The model's numbers (lengths, masses, inertias) are constants of the generated code, as
// Pinocchio-on-CasADi users get them; ours and CasADi's own peers take them as inputs.
// OUT_C also gets a main() that checks nothing but prints, at the leg file's state and
// τ = 0, M, N and q̈ (compared with ours by xtask) and the median time of one call of each
// function, with its inputs prepared once and its outputs preallocated.
#include <pinocchio/autodiff/casadi.hpp>

#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody.hpp>

#include <casadi/casadi.hpp>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "pinocchio_leg.hpp"

namespace pin = pinocchio;
using SX = casadi::SX;

static const char* DRIVER = R"DRIVER(
/* The timing driver (pinocchio_casadi.cpp). */
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now_ns(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return 1e9 * (double)t.tv_sec + (double)t.tv_nsec;
}

static int by_value(const void* a, const void* b) {
  double x = *(const double*)a, y = *(const double*)b;
  return (x > y) - (x < y);
}

typedef int (*casadi_fn)(const casadi_real**, casadi_real**, casadi_int*, casadi_real*, int);

/* Median over 15 batches of 20000 calls of the time of one call. */
static double median_ns(casadi_fn f, const casadi_real** arg, casadi_real** res, volatile double* sink) {
  double times[15];
  for (int b = 0; b < 15; ++b) {
    double t0 = now_ns();
    for (int i = 0; i < 20000; ++i) {
      f(arg, res, 0, 0, 0);
      *sink += res[0][0];
    }
    times[b] = (now_ns() - t0) / 20000.0;
  }
  qsort(times, 15, sizeof(double), by_value);
  return times[7];
}

static void print(const char* key, const casadi_real* x, int n, int first) {
  printf("%s\"%s\": [", first ? "{" : ", ", key);
  for (int i = 0; i < n; ++i) printf("%s%.17g", i ? ", " : "", x[i]);
  printf("]");
}

int main(void) {
  static casadi_real M[NQ * NQ], N[NQ], J[NC * NQ + 1], B[NC + 1], QDD[NQ], F[NC + 1];
  static const casadi_real TAU[NQ] = {0};
  const casadi_real* targ[2] = {STATE_Q, STATE_QD};
  casadi_real* tres[4] = {M, N, J, B};
  const casadi_real* farg[3] = {STATE_Q, STATE_QD, TAU};
  casadi_real* fres[2] = {QDD, F};
  volatile double sink = 0;
  pin_dynamics_terms(targ, tres, 0, 0, 0);
  pin_forward_dynamics(farg, fres, 0, 0, 0);
  print("M", M, NQ * NQ, 1);
  print("N", N, NQ, 0);
  print("qdd", QDD, NQ, 0);
  double terms = median_ns(pin_dynamics_terms, targ, tres, &sink);
  double fd = median_ns(pin_forward_dynamics, farg, fres, &sink);
  printf(", \"terms_median_ns\": %.3f, \"fd_median_ns\": %.3f}\n", terms, fd);
  return 0;
}
)DRIVER";

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: pinocchio_casadi LEG_FILE OUT_C\n");
    return 2;
  }
  Leg leg;
  if (!read_leg(argv[1], leg)) return 1;
  const int nq = leg.model.nq, nc = 2 * int(leg.closures.size());
  typedef pin::ModelTpl<SX> ADModel;
  typedef ADModel::Data ADData;
  typedef Eigen::Matrix<SX, Eigen::Dynamic, 1> ADVector;
  ADModel model = leg.model.cast<SX>();
  ADData data(model);

  // Inputs in the spec's joint order; Pinocchio's own order inside.
  SX q = SX::sym("q", nq), qd = SX::sym("qd", nq), tau = SX::sym("tau", nq);
  ADVector q_ad(nq), v_ad(nq), zero(nq);
  for (int i = 0; i < nq; ++i) {
    q_ad(leg.at[i]) = q(i);
    v_ad(leg.at[i]) = qd(i);
    zero(i) = 0;
  }
  pin::crba(model, data, q_ad);  // the upper triangle of M
  pin::nonLinearEffects(model, data, q_ad, v_ad);
  SX M(nq, nq), N(nq, 1), J(nc, nq), Jdot_qd(nc, 1);
  for (int r = 0; r < nq; ++r) {
    N(r) = data.nle(leg.at[r]);
    for (int c = 0; c < nq; ++c)
      M(r, c) = data.M(std::min(leg.at[r], leg.at[c]), std::max(leg.at[r], leg.at[c]));
  }
  if (nc > 0) {
    pin::forwardKinematics(model, data, q_ad, v_ad, zero);
    pin::computeJointJacobians(model, data, q_ad);
    pin::updateFramePlacements(model, data);
    for (std::size_t k = 0; k < leg.closures.size(); ++k) {
      const auto fa = model.getFrameId(leg.closures[k] + "_a"), fb = model.getFrameId(leg.closures[k] + "_b");
      Eigen::Matrix<SX, 6, Eigen::Dynamic> ja = Eigen::Matrix<SX, 6, Eigen::Dynamic>::Zero(6, nq);
      Eigen::Matrix<SX, 6, Eigen::Dynamic> jb = Eigen::Matrix<SX, 6, Eigen::Dynamic>::Zero(6, nq);
      pin::getFrameJacobian(model, data, fa, pin::LOCAL_WORLD_ALIGNED, ja);
      pin::getFrameJacobian(model, data, fb, pin::LOCAL_WORLD_ALIGNED, jb);
      const auto aa = pin::getFrameClassicalAcceleration(model, data, fa, pin::LOCAL_WORLD_ALIGNED);
      const auto ab = pin::getFrameClassicalAcceleration(model, data, fb, pin::LOCAL_WORLD_ALIGNED);
      for (int r = 0; r < 2; ++r) {
        const int row = 2 * int(k) + r;
        for (int c = 0; c < nq; ++c) J(row, c) = ja(r, leg.at[c]) - jb(r, leg.at[c]);
        Jdot_qd(row) = aa.linear()(r) - ab.linear()(r);
      }
    }
  }
  SX damping(nq, 1);
  for (int i = 0; i < nq; ++i) damping(i) = leg.damping(leg.at[i]);
  SX rhs_top = tau - N - damping * qd;
  SX x;
  if (nc > 0) {
    SX K = SX::vertcat({SX::horzcat({M, -J.T()}), SX::horzcat({J, SX::zeros(nc, nc)})});
    x = solve(K, SX::vertcat({rhs_top, -Jdot_qd}));
  } else {
    x = solve(M, rhs_top);
  }
  SX qdd = x(casadi::Slice(0, nq));
  SX F = nc > 0 ? SX(x(casadi::Slice(nq, nq + nc))) : SX(0, 1);

  std::vector<SX> terms_out = cse(std::vector<SX>{densify(M), densify(N), densify(J), densify(Jdot_qd)});
  std::vector<SX> fd_out = cse(std::vector<SX>{densify(qdd), densify(F)});
  casadi::Function terms("pin_dynamics_terms", {q, qd}, terms_out);
  casadi::Function fd("pin_forward_dynamics", {q, qd, tau}, fd_out);
  casadi::CodeGenerator cg("pin", casadi::Dict{{"with_header", false}});
  cg.add(terms);
  cg.add(fd);

  // The state the driver evaluates at, in the spec's order.
  std::ostringstream state;
  state << "#define NQ " << nq << "\n#define NC " << nc << "\n";
  state.precision(17);
  state << "static const casadi_real STATE_Q[" << nq << "] = {";
  for (int i = 0; i < nq; ++i) state << (i ? ", " : "") << leg.q(leg.at[i]);
  state << "};\nstatic const casadi_real STATE_QD[" << nq << "] = {";
  for (int i = 0; i < nq; ++i) state << (i ? ", " : "") << leg.v(leg.at[i]);
  state << "};\n";

  std::ofstream out(argv[2]);
  out << "/* Pinocchio 4 on casadi::SX, emitted by CasADi's code generator (pinocchio_casadi.cpp). */\n"
      << cg.dump() << "\n" << state.str() << DRIVER;
  out.close();
  if (!out) {
    std::fprintf(stderr, "cannot write %s\n", argv[2]);
    return 1;
  }
  std::printf("{\"instructions_terms\": %lld, \"instructions_fd\": %lld}\n", (long long)terms.n_instructions(),
              (long long)fd.n_instructions());
  return 0;
}
