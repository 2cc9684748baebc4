#pragma once
// `contactgrid validate`: compares a contact set with Bullet on the same scene (docs/FORMAT.md §4).
//
// Comparison: pairs are matched by (id_a, id_b). A pair found by one side only is "missing" (only
// Bullet found it) or "extra" (only the contacts given found it) unless it is borderline: its exact
// signed distance (recomputed from the scene in long double) is within the band
//     band = max(tol(contacts precision), tol(Bullet precision)),  scale = mean bounding radius,
//     tol(fp64 contacts) = max(1e-9·scale, 16·eps64·extent)   extent: largest edge of the scene box
//     tol(fp32 contacts) = max(1e-4·scale, 16·eps32·extent)   (the engine computes in a local frame)
//     tol(double Bullet) = max(1e-9·scale, 16·eps64·magnitude) magnitude: largest |world coordinate|
//     tol(float Bullet)  = 1e-4·scale  (in sphere-only scenes float Bullet works in world coordinates;
//                                       far from the origin it is simply wrong, and that must show)
// where either decision is correct. For matched pairs: position error = max(|Δposition_on_a|,
// |Δposition_on_b|), normal angle in degrees, |Δdistance|.
// Tolerances are relative to the bodies' size: a pair's position limit is pos_eps·L (L: the pair's
// larger bounding radius; the course's 0.1 was for radii of order 1), or pos_abs (scene units) when
// given; the report prints the rule with the verdict.
// PASS iff the contacts obey docs/FORMAT.md §2 (id_a < id_b, sorted, each pair once, ids in range), no pair
// is missing or extra outside the band, every position error is within its limit and every angle
// <= angle_deg. The distance error is reported, not judged (it is bounded by the position errors).
//
// Bullet's frame (bullet_oracle.hpp): Bullet sees every body scaled by bullet_scale(mean bounding
// radius), a power of two, and centred on the bodies of the piece it is given, so its absolute
// thresholds (contact breaking threshold, ellipsoid margin) are the same fraction of the bodies at
// any unit of length; what it returns is reported in the scene's units.
//
// Pieces and memory: the scene is validated region by region. A piece owns the pairs whose body
// id_a has its centre in the piece's box; Bullet runs on the bodies whose centres lie within the box
// grown by 2·r_max (every body that can touch an owned one), so each pair is compared exactly once.
// The whole scene starts as one piece; a piece whose Bullet world would not fit the memory left
// under memory_limit (the limit less what the process holds after reading the scene and the contacts;
// a world takes bullet_cost() bytes per expected Bullet pair and per body, validate.cpp), or holds more
// than 2^17 bodies, is halved at the median centre of its longest axis until it fits. The report gives
// the limit, the pieces and the peak resident memory (this process, and the float Bullet subprocess).
//
// Sampling (sample = K > 0): the centres' box is cut into a lattice of cells holding about
// bodies_per_box body centres each (by default 4000, or fewer in dense scenes: about 4000 contacts), and K
// distinct cells are drawn at random (seeded): disjoint sub-boxes, each a piece as above (so pairs reaching
// out of the box are checked too). The report gives the fraction of the contacts checked. A scene smaller
// than one box is checked whole.
//
// Pairs with an ellipsoid (docs/VALIDATION.md, "Validating ellipsoids"): Bullet collides ellipsoids as a
// convex shape with the exact support and a margin of kEllipsoidMargin in its frame
// (bullet_ellipsoid_shape.hpp), by default in float (double Bullet's EPA is degenerate on 17–20 % of
// ellipsoid pairs). A matched pair agrees when its positions and distances differ by at most its
// position limit and its normals by <= angle_deg. Where they disagree, or one side lacks the pair,
// each side's answer is judged by the contact's optimality conditions (contact_judge.hpp):
//   - matched, disagreeing: our answer fails → our error (FAIL); else Bullet's fails → a Bullet error
//     (listed, accepted); both pass → both valid (two equally deep directions);
//   - only ours: our answer fails → our error (FAIL); it passes and |distance| < the shallow limit
//     (shallow·L, or shallow_abs) → a shallow Bullet miss (listed with its distance, accepted); it
//     passes deeper → a Bullet error;
//   - only Bullet's: the judge's exact distance <= −band → missing (FAIL, a real contact we missed);
//     > band → a Bullet error (Bullet's answer fails the conditions: it invented the contact).
// The judge's length tolerance: our answers 1e-6·L (fp64) or 1e-4·L (fp32) + 16·eps·magnitude (they
// are stored in world coordinates), Bullet's 1e-3·L (its GJK/EPA stop at ~1e-4 relative) + 16·eps·(the
// extent of its frame). Sphere–sphere pairs keep the rule above (Bullet's sphere contacts are exact
// formulas).
#include <cstdint>
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "engine.hpp"
#include "scene/scene.hpp"

namespace cg {

struct ValidateOptions {
  double pos_eps = 0.1;                            // --pos-eps: × L (a pair's larger bounding radius)
  std::optional<double> pos_abs;                   // --pos-abs: an absolute limit instead (scene units)
  double angle_deg = 10.0;                         // --angle-deg
  std::optional<Precision> bullet;                 // --bullet-precision double|float; unset (auto):
                                                   // float for scenes with ellipsoids, else double
  std::uint64_t sample = 0;                        // --sample K: K random sub-boxes; 0 = whole scene
  std::uint64_t seed = 1;                          // --seed: picks the sub-boxes
  std::uint64_t bodies_per_box = 0;                // target body count of one sub-box; 0: 4000, or
                                                   // fewer so that a box owns about 4000 contacts
  Precision contacts_precision = Precision::fp64;  // precision the contacts were computed in
                                                   // (validate_files takes it from the file)
  std::size_t max_offenders = 8;                   // listed per kind in the report
  double shallow = 0.01;                           // --shallow: shallow Bullet misses have |distance|
                                                   // below this × L (a quarter of Bullet's ellipsoid
                                                   // margin in its frame, where L is about 1)
  std::optional<double> shallow_abs;               // --shallow-abs: an absolute threshold instead
  std::uint64_t memory_limit = 0;                  // --memory: bytes; 0: default_memory_limit()
  std::uint64_t piece_bytes = 0;                   // the Bullet memory one piece may take (tests);
                                                   // 0: what memory_limit leaves
  bool progress = false;                           // a progress line on stderr (a terminal only)
};

// The default memory limit: 4 GiB or half the machine's memory, whichever is smaller.
std::uint64_t default_memory_limit();
// validate's --memory: io/size_text.hpp's parse_size ("4G", "512M", "1.5GiB", "800000000" -> bytes).
std::uint64_t parse_memory(const std::string& text);

// "double" | "float" (also "fp64" | "fp32") -> Precision, "auto" -> unset; UsageError otherwise.
std::optional<Precision> parse_bullet_precision(const std::string& name);

struct ValidateOffender {
  enum class Kind { missing, extra, position, angle, distance, ours_wrong, bullet_wrong, shallow_miss };
  static constexpr std::size_t kinds = 8;
  Kind kind;
  std::int64_t id_a = 0, id_b = 0;
  double value = 0;              // position error, angle (deg), distance error, or |exact distance|
  double exact_distance = 0;     // recomputed from the scene in long double
  double contacts_distance = 0;  // NaN when the contacts lack the pair
  double bullet_distance = 0;    // NaN when Bullet lacks the pair
  std::string reason;            // judged pairs: the condition that failed (or why it is accepted)
};
const char* to_string(ValidateOffender::Kind k);

struct ValidateReport {
  bool pass = false;
  std::vector<std::string> failures;  // one line per failed criterion or contract violation
  std::vector<std::string> notes;     // the Bullet frame, sampling fallbacks, …

  // What was compared.
  Precision bullet = Precision::fp64;
  std::uint64_t sample_boxes = 0;     // 0: whole scene
  std::uint64_t contacts = 0;         // rows of the contacts given
  std::uint64_t checked = 0;          // of which compared with Bullet
  std::uint64_t bullet_contacts = 0;  // Bullet's contacts in the compared region(s)
  std::uint64_t matched = 0;
  std::uint64_t missing = 0, extra = 0;                        // outside the band
  std::uint64_t borderline_missing = 0, borderline_extra = 0;  // inside the band (accepted)

  // Pairs with an ellipsoid (see the rules above).
  std::uint64_t shape_matched = 0, shape_agree = 0;              // matched; of which within the tolerances
  std::uint64_t judged = 0;                                      // pairs judged (disagreeing or one-sided)
  std::uint64_t our_errors = 0;                                  // our answers failing the conditions (FAIL)
  std::uint64_t bullet_errors = 0;                               // Bullet's answers failing them (accepted)
  std::uint64_t both_valid = 0;                                  // disagreeing, and both answers pass
  std::uint64_t shallow_misses = 0;                              // ours only, shallow, ours passes (accepted)
  double shallow_deepest = 0;                                    // the largest |distance| among them
  double shape_max_position_error = 0, shape_max_angle_deg = 0;  // matched, relative / degrees

  // Contract violations of the contacts given (docs/FORMAT.md §2).
  std::uint64_t bad_id_order = 0, unsorted = 0, duplicates = 0, bad_ids = 0, non_finite = 0;

  // Geometry of the matched pairs.
  double max_position_error = 0, max_angle_deg = 0, max_distance_error = 0;

  // Criteria used.
  double pos_eps = 0, angle_deg = 0, band = 0, scale = 0, shallow = 0;
  std::optional<double> pos_abs, shallow_abs;
  double r_min = 0, r_max = 0;  // the bodies' bounding radii (for the printed limits)
  double bullet_seconds = 0;
  double max_position_rel = 0;  // sphere pairs: the largest position error / L

  // Bullet's frame and the pieces.
  double bullet_scale = 1;
  std::uint64_t pieces = 0, largest_piece = 0;              // Bullet worlds run; bodies in the largest
  std::uint64_t bullet_pairs = 0, largest_piece_pairs = 0;  // Bullet's overlapping pairs: all, most in one
  std::uint64_t memory_limit = 0;
  std::uint64_t peak_bytes = 0, child_peak_bytes = 0;  // peak resident memory: this process, float Bullet

  // The limits of a pair whose larger bounding radius is L.
  double position_limit(double L) const { return pos_abs ? *pos_abs : pos_eps * L; }
  double shallow_limit(double L) const { return shallow_abs ? *shallow_abs : shallow * L; }

  std::vector<ValidateOffender> offenders;  // worst first within each kind

  double checked_fraction() const { return contacts ? double(checked) / double(contacts) : 1.0; }
  // "validate: PASS|FAIL …" followed by the statistics, the failures and the worst offenders.
  std::string text() const;
};

// Compares `contacts` (any order: violations are reported, and the comparison still runs on the
// contacts put in canonical form) with Bullet on `scene`. Throws InputError when the contact arrays
// have inconsistent lengths, UsageError for bad options, IoError when float Bullet cannot be run.
ValidateReport validate(const Scene& scene, const Contacts<double>& contacts, const ValidateOptions& options);

// read_scene + read_contacts (src/io/scene_file.hpp, src/io/contact_file.hpp), then validate();
// contacts_precision is taken from the contact file's `precision` attribute.
ValidateReport validate_files(const std::string& scene_path, const std::string& contacts_path,
                              ValidateOptions options);

}  // namespace cg
