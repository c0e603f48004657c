// The simulated world's atmosphere: a spherical shell with exponentially distributed Rayleigh
// molecules and Mie aerosols, three colour bands (~680/550/440 nm). Sunlight is attenuated
// along slant paths; the sky is single-scattered sunlight ray-marched per view direction
// (Nishita-style, transmittance to the sun at each sample) plus a small documented isotropic
// multiple-scattering term. Independent of the solver's sky model (solve/sky_model.h).
#pragma once

#include <Eigen/Core>
#include <vector>

namespace rouen {

struct AtmosphereParams {
  double earth_radius_m = 6371e3;
  double top_altitude_m = 80e3;  // above sea level
  double rayleigh_scale_m = 8000.0;
  double mie_scale_m = 1200.0;
  // Sea-level Rayleigh scattering coefficients (1/m) at 680, 550, 440 nm.
  Eigen::Vector3d rayleigh_sea_level = Eigen::Vector3d(5.8e-6, 13.5e-6, 33.1e-6);
  Eigen::Vector3d wavelength_nm = Eigen::Vector3d(680.0, 550.0, 440.0);
  double visibility_km = 35.0;  // Koschmieder (3.912 / total extinction at 550 nm, sea level)
  double angstrom = 1.3;        // aerosol extinction ~ lambda^-angstrom
  double mie_albedo = 0.9;      // aerosol single-scattering albedo
  double mie_g = 0.76;          // Cornette-Shanks asymmetry
  // Multiple scattering approximated as an isotropic source of radiance equal to the mean
  // single-scattered sky radiance (horizontal sky irradiance / pi) times this factor, seen
  // through the view path's scattering depth: L_ms = f * E_h / pi * (1 - exp(-tau_s)).
  double multiple_scattering = 0.7;
  // Top-of-atmosphere band irradiance (W/m^2 per ~100 nm band) at 1 AU.
  Eigen::Vector3d solar_toa = Eigen::Vector3d(150.0, 185.0, 175.0);

  // Throws rouen::Error naming the bad parameter.
  void Validate() const;
  // Aerosol extinction at sea level per band (1/m).
  Eigen::Vector3d MieExtinction() const;
};

class Atmosphere {
 public:
  explicit Atmosphere(const AtmosphereParams& params = {});
  const AtmosphereParams& params() const { return p_; }

  // Optical depth per band from altitude h (m above sea level) to space along a ray with
  // cosine-of-zenith mu; +infinity when the ray meets the ground sphere. Table lookup.
  Eigen::Vector3d OpticalDepth(double h, double mu) const;
  // The same by direct numerical integration (slow; for the table and tests).
  Eigen::Vector3d OpticalDepthExact(double h, double mu) const;
  Eigen::Vector3d Transmittance(double h, double mu) const;

  struct Scatter {
    Eigen::Vector3d radiance = Eigen::Vector3d::Zero();       // single scattering, W m^-2 sr^-1
    Eigen::Vector3d scatter_depth = Eigen::Vector3d::Zero();  // along the view path
  };
  // Single-scattered radiance seen from altitude h_obs towards unit `view` (local frame,
  // z up; views below the horizontal are clamped to it), for sunlight from unit `sun` with
  // band irradiance `sun_toa` above the atmosphere.
  Scatter SingleScatter(double h_obs, const Eigen::Vector3d& view, const Eigen::Vector3d& sun,
                        const Eigen::Vector3d& sun_toa, int steps = 128) const;
  // The same for a row of views at elevation `el` (rad) and azimuths k * pi / (n - 1)
  // relative to a sun at elevation `sun_el` (rad), sharing the view-path work. Writes n
  // radiances and scattering depths.
  void SingleScatterRow(double h_obs, double el, double sun_el, const Eigen::Vector3d& sun_toa,
                        int n, Scatter* out, int steps = 128) const;

 private:
  Eigen::Vector2d DensityIntegralsExact(double h, double mu) const;  // (Rayleigh, Mie) m
  struct Altitude {  // table interpolation state for one altitude
    int i0 = 0;
    double a = 0, mu_h = 0;
  };
  Altitude AltitudeSlot(double h) const;
  Eigen::Vector3d TransmittanceAt(const Altitude& alt, double mu) const;
  AtmosphereParams p_;
  Eigen::Vector3d mie_ext_, mie_sca_;
  int nh_ = 0, nt_ = 0;
  std::vector<Eigen::Vector2f> table_;  // density integrals (Rayleigh, Mie), metres
};

// Where SkyTable looks a unit ENU direction up: its elevation (rad, 0 for directions below the
// horizon) and azimuth (rad from north through east), rounded to float. The same for every sun,
// so a direction's angles can be found once for many skies.
struct SkyAngles {
  float elevation = 0, azimuth = 0;
  static SkyAngles Of(const Eigen::Vector3d& dir);
};

// The clear sky for one sun position: single + approximate multiple scattering tabulated over
// view elevation (dense near the horizon) and azimuth relative to the sun, bilinear between.
class SkyTable {
 public:
  SkyTable() = default;
  // `sun_dir`: unit ENU vector to the sun; `sun_toa`: band irradiance above the atmosphere.
  SkyTable(const Atmosphere& atmosphere, double observer_altitude_m, const Eigen::Vector3d& sun_dir,
           const Eigen::Vector3d& sun_toa);

  // Radiance (W m^-2 sr^-1 per band) towards a unit ENU direction. Directions below the
  // horizon return the horizon value (the world puts ground there).
  Eigen::Vector3d Radiance(const Eigen::Vector3d& dir) const;
  // The same for a direction's angles (equal to Radiance(dir) up to their float rounding).
  Eigen::Vector3d Radiance(const SkyAngles& angles) const;
  // Irradiance on a plane with unit normal n from the unoccluded sky above the horizon.
  Eigen::Vector3d PlaneIrradiance(const Eigen::Vector3d& n) const;
  Eigen::Vector3d HorizontalIrradiance() const { return horizontal_; }

 private:
  Eigen::Vector3d Lookup(const std::vector<Eigen::Vector3f>& t, double el, double dphi) const;
  Eigen::Vector3d RadianceAt(double el, double az) const;
  int ne_ = 0, na_ = 0;
  Eigen::Vector3d sun_dir_ = Eigen::Vector3d::UnitZ();
  double sun_az_ = 0;
  std::vector<Eigen::Vector3f> radiance_;
  Eigen::Vector3d horizontal_ = Eigen::Vector3d::Zero();
  // Quadrature over the upper hemisphere for PlaneIrradiance: direction and L * dOmega.
  std::vector<Eigen::Vector3f> quad_dir_, quad_w_;
};

}  // namespace rouen
