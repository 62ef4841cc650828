// Pinocchio's constrained forward dynamics of a spatial leg, timed: the benchmarks' C++
// peer for spatial legs (`cargo xtask bench --pinocchio` builds and runs it; not part of
// CI). The model is Pinocchio's own URDF parser's reading of `cargo xtask export NAME
// --format urdf` (a ball joint as three revolute joints, so its coordinates are ours); the
// closures are 3-D point constraints between the frames `<closure>.a` and `<closure>.b`,
// as a Pinocchio user writes loop closures.
//
// usage: pinocchio_spatial_bench URDF STATE_FILE
//
// STATE_FILE, one item per line: `gravity gx gy gz`; `joint NAME` per coordinate in our
// order; `armature NAME VALUE`; `closure NAME`; `q …`, `v …`, `tau …` in our order (tau is
// the generalized force B u − D q̇ − the springs' ∂V/∂q: Pinocchio models neither damping
// nor springs, so its call does those few products less than ours).
//
// One call = `constraintDynamics` with ProximalSettings(accuracy 1e-12, μ 1e-8, at most
// 100 iterations): converged, it is the exact constrained solution, redundant rows
// included. It is also timed at one proximal iteration (Pinocchio's fastest setting; its q̈
// is then the regularized one). Prints one JSON object: qdd (ours order, converged),
// iterations (the converged solve's), median_ns, one_iteration_qdd, one_iteration_ns.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <pinocchio/multibody.hpp>
#include <pinocchio/parsers/urdf.hpp>
#include <pinocchio/algorithm/constrained-dynamics.hpp>

namespace pin = pinocchio;

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: pinocchio_spatial_bench URDF STATE_FILE\n");
    return 2;
  }
  pin::Model model;
  pin::urdf::buildModel(argv[1], model);
  std::ifstream in(argv[2]);
  if (!in) {
    std::fprintf(stderr, "%s: cannot read\n", argv[2]);
    return 1;
  }
  std::vector<std::string> joints, closures;
  std::vector<double> q_ours, v_ours, tau_ours;
  std::string line;
  auto numbers = [](std::istringstream& s) {
    std::vector<double> v;
    double x;
    while (s >> x) v.push_back(x);
    return v;
  };
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string key;
    s >> key;
    if (key == "gravity") {
      double gx, gy, gz;
      s >> gx >> gy >> gz;
      model.gravity.linear() << gx, gy, gz;
    } else if (key == "joint") {
      std::string n;
      s >> n;
      joints.push_back(n);
    } else if (key == "armature") {
      std::string n;
      double a;
      s >> n >> a;
      model.armature[model.joints[model.getJointId(n)].idx_v()] = a;
    } else if (key == "closure") {
      std::string n;
      s >> n;
      closures.push_back(n);
    } else if (key == "q") {
      q_ours = numbers(s);
    } else if (key == "v") {
      v_ours = numbers(s);
    } else if (key == "tau") {
      tau_ours = numbers(s);
    }
  }
  const int n = int(joints.size());
  if (model.nv != n) {
    std::fprintf(stderr, "%s: %d coordinates, Pinocchio's model has nv = %d\n", argv[2], n, model.nv);
    return 1;
  }
  if (int(q_ours.size()) != n || int(v_ours.size()) != n || int(tau_ours.size()) != n) {
    std::fprintf(stderr, "%s: q, v and tau need %d values each\n", argv[2], n);
    return 1;
  }
  // Our coordinate i is Pinocchio's velocity entry vidx[i]; a revolute (`continuous`)
  // joint's configuration is (cos, sin), a prismatic one's the value.
  std::vector<int> vidx(n);
  Eigen::VectorXd q = pin::neutral(model), v = Eigen::VectorXd::Zero(model.nv), tau = v;
  for (int i = 0; i < n; ++i) {
    const auto id = model.getJointId(joints[i]);
    if (id >= model.joints.size()) {
      std::fprintf(stderr, "%s: no joint `%s` in the URDF\n", argv[2], joints[i].c_str());
      return 1;
    }
    const auto& j = model.joints[id];
    vidx[i] = j.idx_v();
    if (j.nq() == 2) {
      q(j.idx_q()) = std::cos(q_ours[i]);
      q(j.idx_q() + 1) = std::sin(q_ours[i]);
    } else {
      q(j.idx_q()) = q_ours[i];
    }
    v(j.idx_v()) = v_ours[i];
    tau(j.idx_v()) = tau_ours[i];
  }
  std::vector<pin::RigidConstraintModel> cmodels;
  for (const auto& c : closures) {
    const auto ia = model.getFrameId(c + ".a"), ib = model.getFrameId(c + ".b");
    if (ia >= model.frames.size() || ib >= model.frames.size()) {
      std::fprintf(stderr, "%s: no frames `%s.a`, `%s.b` in the URDF\n", argv[2], c.c_str(), c.c_str());
      return 1;
    }
    const pin::Frame& fa = model.frames[ia];
    const pin::Frame& fb = model.frames[ib];
    const bool swap = fa.parentJoint == 0;
    const pin::Frame& f1 = swap ? fb : fa;
    const pin::Frame& f2 = swap ? fa : fb;
    cmodels.emplace_back(pin::CONTACT_3D, model, f1.parentJoint, f1.placement, f2.parentJoint, f2.placement,
                         pin::LOCAL_WORLD_ALIGNED);
  }
  std::vector<pin::RigidConstraintData> cdatas;
  for (const auto& cm : cmodels) cdatas.emplace_back(cm);
  pin::Data data(model);
  pin::initConstraintDynamics(model, data, cmodels, cdatas);

  auto timed = [&](pin::ProximalSettings& settings, Eigen::VectorXd& out) {
    out = pin::constraintDynamics(model, data, q, v, tau, cmodels, cdatas, settings);
    // Median over batches of the time of one call, on states that change every call (a
    // rate: a revolute joint's (cos, sin) stays a unit pair).
    const int batch = 20000, batches = 15;
    std::vector<double> times;
    Eigen::VectorXd vv = v;
    double sink = 0;
    for (int b = 0; b < batches; ++b) {
      auto t0 = std::chrono::steady_clock::now();
      for (int i = 0; i < batch; ++i) {
        vv(0) = v(0) + 1e-12 * i;
        sink += pin::constraintDynamics(model, data, q, vv, tau, cmodels, cdatas, settings)(0);
      }
      auto t1 = std::chrono::steady_clock::now();
      times.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count() / batch);
    }
    std::sort(times.begin(), times.end());
    if (!std::isfinite(sink)) std::fprintf(stderr, "non-finite q̈ while timing\n");
    return times[times.size() / 2];
  };
  pin::ProximalSettings converged(1e-12, 1e-8, 100), one(1e-12, 1e-8, 1);
  Eigen::VectorXd qdd, qdd_one;
  const double ns = timed(converged, qdd);
  pin::constraintDynamics(model, data, q, v, tau, cmodels, cdatas, converged);
  const int iterations = converged.iter;
  const double ns_one = timed(one, qdd_one);
  auto print = [&](const char* key, const Eigen::VectorXd& x) {
    std::printf("\"%s\": [", key);
    for (int i = 0; i < n; ++i) std::printf("%s%.17g", i ? ", " : "", x(vidx[i]));
    std::printf("]");
  };
  std::printf("{");
  print("qdd", qdd);
  std::printf(", \"iterations\": %d, \"median_ns\": %.3f, ", iterations, ns);
  print("one_iteration_qdd", qdd_one);
  std::printf(", \"one_iteration_ns\": %.3f}\n", ns_one);
  return 0;
}
