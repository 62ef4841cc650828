// The leg file that `cargo xtask bench --pinocchio` writes from a spec, read into a
// Pinocchio model: shared by pinocchio_bench.cpp (Pinocchio's algorithms in double) and
// pinocchio_casadi.cpp (the same algorithms on casadi::SX, emitted as C).
//
//   gravity GX GY
//   link NAME PARENT OX OY MASS CX CY INERTIA ARMATURE DAMPING   (PARENT: -1 for the base)
//   closure NAME LINK_A AX AY LINK_B BX BY                        (LINK: -1 for the base)
//   state Q... QD...
//
// Revolute joints about z, the spec's masses, centres of mass and inertias, reflected rotor
// inertia as armature, closure frames `<closure>_a` / `<closure>_b`.
#pragma once
#include <cstdio>
#include <string>
#include <vector>

#include <pinocchio/multibody.hpp>

struct Leg {
  pinocchio::Model model;
  std::vector<std::string> closures;
  // In Pinocchio's joint order: the state and the joints' viscous damping.
  Eigen::VectorXd q, v, damping;
  // at[i]: where the spec's joint i is in Pinocchio's order.
  std::vector<int> at;
};

namespace leg_file {
struct Link {
  std::string name;
  int parent;
  double ox, oy, m, cx, cy, inertia, arm, d;
};
struct Closure {
  std::string name;
  int la, lb;
  double ax, ay, bx, by;
};

inline bool parse(std::FILE* f, Leg& leg, std::vector<Link>& links, std::vector<Closure>& closures,
                  std::vector<double>& state) {
  char kind[32], name[128];
  while (std::fscanf(f, "%31s", kind) == 1) {
    const std::string k = kind;
    if (k == "gravity") {
      double gx, gy;
      if (std::fscanf(f, "%lf %lf", &gx, &gy) != 2) return false;
      leg.model.gravity.linear(Eigen::Vector3d(gx, gy, 0.0));
    } else if (k == "link") {
      Link l;
      if (std::fscanf(f, "%127s %d %lf %lf %lf %lf %lf %lf %lf %lf", name, &l.parent, &l.ox, &l.oy, &l.m,
                      &l.cx, &l.cy, &l.inertia, &l.arm, &l.d) != 10)
        return false;
      if (l.parent >= int(links.size())) return false;
      l.name = name;
      links.push_back(l);
    } else if (k == "closure") {
      Closure c;
      if (std::fscanf(f, "%127s %d %lf %lf %d %lf %lf", name, &c.la, &c.ax, &c.ay, &c.lb, &c.bx, &c.by) != 7)
        return false;
      // -1: a point fixed in the base frame.
      if (c.la < -1 || c.lb < -1 || c.la >= int(links.size()) || c.lb >= int(links.size())) return false;
      c.name = name;
      closures.push_back(c);
    } else if (k == "state") {
      double x;
      for (std::size_t i = 0; i < 2 * links.size(); ++i) {
        if (std::fscanf(f, "%lf", &x) != 1) return false;
        state.push_back(x);
      }
    } else {
      std::fprintf(stderr, "unknown line `%s`\n", kind);
      return false;
    }
  }
  return true;
}
}  // namespace leg_file

// Reads `path` into `leg`; false (with a message on stderr) if it cannot.
inline bool read_leg(const char* path, Leg& leg) {
  namespace pin = pinocchio;
  std::FILE* f = std::fopen(path, "r");
  if (!f) {
    std::fprintf(stderr, "cannot read %s\n", path);
    return false;
  }
  std::vector<leg_file::Link> links;
  std::vector<leg_file::Closure> closure_lines;
  std::vector<double> state;
  const bool parsed = leg_file::parse(f, leg, links, closure_lines, state);
  std::fclose(f);
  const int nq = int(links.size());
  if (!parsed || int(state.size()) != 2 * nq) {
    std::fprintf(stderr, "%s: not a leg file\n", path);
    return false;
  }
  // Pinocchio's algorithms need the joints in depth-first order (each subtree's velocity
  // indices contiguous); a spec lists links in any order with parents first.
  std::vector<int> order, stack;
  for (int i = nq - 1; i >= 0; --i)
    if (links[i].parent < 0) stack.push_back(i);
  while (!stack.empty()) {
    const int i = stack.back();
    stack.pop_back();
    order.push_back(i);
    for (int c = nq - 1; c >= 0; --c)
      if (links[c].parent == i) stack.push_back(c);
  }
  leg.at.assign(nq, 0);
  std::vector<pin::JointIndex> joints(nq);
  for (int k = 0; k < nq; ++k) {
    const leg_file::Link& l = links[order[k]];
    leg.at[order[k]] = k;
    const pin::JointIndex p = l.parent < 0 ? 0 : joints[l.parent];
    const pin::JointIndex j = leg.model.addJoint(
        p, pin::JointModelRZ(), pin::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(l.ox, l.oy, 0)), l.name);
    leg.model.appendBodyToJoint(
        j,
        pin::Inertia(l.m, Eigen::Vector3d(l.cx, l.cy, 0),
                     Eigen::Vector3d(l.inertia, l.inertia, l.inertia).asDiagonal()),
        pin::SE3::Identity());
    joints[order[k]] = j;
  }
  for (const leg_file::Closure& c : closure_lines) {
    leg.model.addFrame(pin::Frame(c.name + "_a", c.la < 0 ? 0 : joints[c.la],
                                  pin::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(c.ax, c.ay, 0)),
                                  pin::OP_FRAME));
    leg.model.addFrame(pin::Frame(c.name + "_b", c.lb < 0 ? 0 : joints[c.lb],
                                  pin::SE3(Eigen::Matrix3d::Identity(), Eigen::Vector3d(c.bx, c.by, 0)),
                                  pin::OP_FRAME));
    leg.closures.push_back(c.name);
  }
  leg.q.resize(nq);
  leg.v.resize(nq);
  leg.damping.resize(nq);
  for (int i = 0; i < nq; ++i) {
    leg.model.armature(leg.at[i]) = links[i].arm;
    leg.damping(leg.at[i]) = links[i].d;
    leg.q(leg.at[i]) = state[i];
    leg.v(leg.at[i]) = state[nq + i];
  }
  return true;
}
