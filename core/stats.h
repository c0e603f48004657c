// Order statistics with one rounding rule for the whole tree.
#pragma once

#include <vector>

namespace rouen {

// The p-quantile (0 <= p <= 1, clamped) of `v` by the lower nearest rank: the element of rank
// floor(p (n - 1)) in ascending order (p = 0.5 of an even count is the lower middle). 0 for an
// empty vector. Takes `v` by value: it is partially reordered.
double Quantile(std::vector<double> v, double p);
float Quantile(std::vector<float> v, double p);

// The p-quantile of `v` where element i counts with weight w[i] (> 0; a solid angle, say): in
// ascending order, the last element whose preceding weight is at most p (W - w_last), W the
// total and w_last the largest value's weight. Equal weights give Quantile(v, p). 0 for an
// empty vector; `v` and `w` must have the same size.
double WeightedQuantile(const std::vector<double>& v, const std::vector<double>& w, double p);

// The sample median: the middle element, or the mean of the two middle ones for an even count
// (the robust centre the solvers estimate with; reports use Quantile). 0 for an empty vector.
double Median(std::vector<double> v);
float Median(std::vector<float> v);

// Arithmetic mean; 0 for an empty vector.
double Mean(const std::vector<double>& v);

}  // namespace rouen
