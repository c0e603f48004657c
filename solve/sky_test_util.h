// Helpers shared by the sky-fit tests (not part of the library API).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "solve/internal/sky_cost.h"

namespace rouen::testing {

// Compares the cost's analytic Jacobian at p0 (eq. 9's 7 parameters) with central differences
// of step h_rel x max(1, |p0_k|), within tol x max(1, |numeric|) per entry.
inline void ExpectJacobianMatchesCentralDifferences(const internal::SkyCost& cost, int n,
                                                    const double (&p0)[7], double h_rel, double tol,
                                                    const std::string& label) {
  std::vector<double> r(n), jac(n * 7), rp(n), rm(n);
  double* jacs[1] = {jac.data()};
  const double* params[1] = {p0};
  ASSERT_TRUE(cost.Evaluate(params, r.data(), jacs));
  for (int k = 0; k < 7; ++k) {
    const double h = h_rel * std::max(1.0, std::abs(p0[k]));
    double q[7];
    std::copy(p0, p0 + 7, q);
    const double* qparams[1] = {q};
    q[k] = p0[k] + h;
    ASSERT_TRUE(cost.Evaluate(qparams, rp.data(), nullptr));
    q[k] = p0[k] - h;
    ASSERT_TRUE(cost.Evaluate(qparams, rm.data(), nullptr));
    for (int i = 0; i < n; ++i) {
      const double numeric = (rp[i] - rm[i]) / (2 * h);
      EXPECT_NEAR(jac[i * 7 + k], numeric, tol * std::max(1.0, std::abs(numeric)))
          << label << "residual " << i << " parameter " << k;
    }
  }
}

}  // namespace rouen::testing
