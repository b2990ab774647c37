// Granule DEM, CPU/OpenMP reference backend (Leach & Marais 2014 §4; Bell et al. 2005;
// Longmore et al. 2013; Cundall & Strack 1979 for the tangential spring).
//
// One Simulation is one particle patch: tetrahedral granules (4 spheres, one rigid body
// each) and rigid shells (many spheres, one body; static, kinematic or dynamic), inside a
// box with a bedrock floor, optional side walls and an optional terrain height grid outside
// the filled region. Everything inside is float, in simulation units (unit particle scale,
// patch-relative); ParticleScale maps to the world. y is up.
//
// The step (Simulation::step), per substep:
//   1. rebuild   sphere positions/velocities from the bodies
//   2. grid      when a sphere moved more than skin/2 since the last rebuild: counting-sort
//                the spheres by cell (cell = 2 r_max + skin, no cap) and rebuild the Verlet
//                neighbour list from the cells after each sphere's (half of the 27: each
//                pair met once), carrying each pair's spring over
//   3. contacts  each pair is computed once, by its owner's entry (lower sorted index; 8 pairs at
//                a time by the AVX2 kernel when the CPU has it, contact_simd.hpp, same bits),
//                and added to both spheres' sums; slabs of two z-layers of cells, the even
//                ones in parallel, then the odd ones: a fixed order of additions (no atomics)
//   4. bodies    bodies in cell-sorted order; each reads its spheres' sums (and zeroes them),
//                adds the boundaries and sums its spheres in sphere-id order
//   5. integrate symplectic Euler; quaternions normalised; NaN check; spheres rebuilt with
//                the velocity the next contact stage sees (SimulationDef::contact_timing)
// The same state in, the same state out, for any number of threads (a test).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "particles/granule.hpp"
#include "particles/material.hpp"
#include "particles/math.hpp"
#include "particles/scale.hpp"

namespace sandpatch {

enum class MotionType : std::uint32_t { Static, Kinematic, Dynamic };

struct BodyId {
  std::int32_t index = -1;
  bool valid() const { return index >= 0; }
};

// Terrain outside the filled region as a small regular height grid (sim units): height
// h(x, z) is bilinear between samples heights[iz * nx + ix] at (x0 + ix*spacing,
// z0 + iz*spacing), clamped at the grid edge. The terrain is solid up to h: spheres whose
// (x, z) lie outside the filled rectangle [fill_min, fill_max] rest on the plane through h
// with the grid's normal; inside, the rectangle's sides are walls up to the outside h (when
// side_walls is off), so a patch is held by the soil around it.
struct TerrainGrid {
  int nx = 0, nz = 0;
  float x0 = 0, z0 = 0, spacing = 1;
  std::vector<float> heights;
  float fill_min_x = 0, fill_min_z = 0, fill_max_x = 0, fill_max_z = 0;
  bool empty() const { return heights.empty(); }
  float height(float x, float z) const;
  Vec3 normal(float x, float z) const;
};

struct SimulationDef {
  // capacities (fixed; exceeding one returns an Error naming it)
  int max_bodies = 1024;                 // granules + shells
  int max_particles = 4096;              // spheres of granules (4 each) + shell spheres

  // granules
  float particle_radius = 0.005f;        // r, m (sim units): radius of a granule's spheres
  float granule_edge_factor = 1.0f;      // s: tetrahedron edge = 2 r s, in [0.5, 1.0]
  Material material;

  // world coupling
  ParticleScale scale;                   // sim <-> world mapping (default: unit, origin 0)
  Vec3 gravity_world{0.0f, -9.81f, 0.0f};  // m/s^2 (world); the sim uses scale.gravity_to_sim

  // domain (sim units): the grid covers [bounds_min, bounds_max]; spheres outside are kept
  // (binned into the border cells) but slow the search
  Vec3 bounds_min{-0.5f, 0.0f, -0.5f};
  Vec3 bounds_max{0.5f, 0.5f, 0.5f};
  float floor_height = 0.0f;             // bedrock plane y = floor_height (m)
  bool side_walls = false;               // planes x = bounds_min.x/max.x, z = bounds_min.z/max.z
  TerrainGrid terrain;                   // optional

  // grid
  float cell_skin = 0.0f;                // m added to the cell size 2 r_max; 0 -> 0.2 r

  // stability guard
  int accuracy_steps_per_contact = 20;   // N: substep dt <= t_c / N
  int max_substeps = 64;                 // refuse frames that would need more
  // Contact timing correction (docs/dem.md "Step size"): the contact stage sees the sphere
  // velocities predicted to its time (v + (dt/2) a) and a contact's first substep gets the
  // matching dashpot. With it a single collision's restitution and contact time are within
  // 2 % at dt <= t_c/50 for e in {0.1, 0.5, 0.9}; without it e = 0.1 is off by -17 ... +2 %.
  // Auto: on when accuracy_steps_per_contact >= 50 (the guard then keeps dt <= t_c/50), off at
  // coarser steps, where the prediction made resting contacts livelier (measured at the
  // manager's t_c/20: a patch under a resting body no longer fell asleep, and the round trip's
  // fill moved 0.116 d in its first second against 0.096 d without). On: always (tests that
  // choose dt themselves); Off: never (the plain dashpot, velocities half a step old).
  enum class ContactTiming { Auto, On, Off };
  ContactTiming contact_timing = ContactTiming::Auto;
  // Overlap guard (0 = off): refuse what would overlap a contact by more than this fraction
  // f of the smaller radius r (default 2: beyond 2 r the centres of two equal spheres can
  // cross and bodies pass through each other):
  //   step():    a body moving at speed s (|v| + |w| arm) hitting something immovable
  //              overlaps by s sqrt(m_pt/k_n) (m_pt: its point effective mass; the lightest
  //              dynamic body's for a kinematic shell): refused when > f r;
  //   add_shell: a dynamic shell's weight shared by all its spheres overlaps each by at
  //              least m |g| / (n k_n): refused when > f r.
  float max_overlap_fraction = 2.0f;

  // sleep
  float sleep_speed = 0.005f;            // m/s (sim units): asleep when every granule is slower
  float sleep_time = 0.5f;               // s held below sleep_speed
  // Sleeping regions (CPU backend; the GL backend refuses it): a granule that has stayed within
  // 0.1 sphere radii of one place for region_sleep_time, whose column of the bed and the columns
  // around it hold no granule that has not and no moving shell near, is frozen where it lies
  // (no integration, no pairs with other frozen granules, its contact history kept) until
  // motion comes near. docs/dem.md "Sleeping regions".
  bool sleep_regions = false;
  float region_sleep_time = 0;           // s a granule stays still before its region may sleep; 0: sleep_time

  int threads = 0;                       // OpenMP threads; 0 = OpenMP's default
};

struct ShellDef {
  std::vector<Vec3> offsets;             // sphere centres in the body frame (about the COM), m
  std::vector<float> radii;              // one radius per sphere, or a single radius for all
  MotionType motion = MotionType::Static;
  float mass = 0;                        // kg (dynamic only)
  Vec3 inertia{0, 0, 0};                 // principal moments, body frame, kg m^2 (dynamic only)
  Vec3 position{};
  Quat orientation{};
  Vec3 velocity{};                       // m/s (kinematic and dynamic)
  Vec3 angular_velocity{};               // rad/s, world frame
  // Collision group (>= 0): the spheres of two bodies of the same group > 0 do not touch
  // (bodies joined by joints, which Bullet does not collide either); granules touch every
  // group. 0: none (touches every other body). Changed later by Simulation::set_body_group.
  std::int32_t group = 0;
};

// What a body of a shell needs, derived from a checked ShellDef: shared by both backends'
// add_shell, so they accept and refuse exactly the same shells with the same errors.
struct ShellPlan {
  int count = 0;                // spheres
  bool one_radius = false;      // radii holds a single radius for all spheres
  std::uint32_t flags = 0;      // BodyFlags motion bits
  float inv_mass = 0;           // 1/kg (dynamic only)
  Vec3 inv_inertia{};           // 1/(kg m^2), principal, body frame (dynamic only)
  float max_radius = 0;         // m
  float arm = 0;                // m, farthest sphere centre from the centre of mass
};
// Checks `sh` and the free capacity (bodies_used of max_bodies, particles_used of
// max_particles); errors name the ShellDef field or the capacity to raise.
Result<ShellPlan> plan_shell(const ShellDef& sh, int bodies_used, int max_bodies, int particles_used,
                             int max_particles);

struct StepStats {
  int substeps = 0;
  double substep_dt = 0;                 // s
  std::int64_t contacts = 0;             // sphere-sphere contacts (pairs) at the last substep
  std::int64_t wall_contacts = 0;        // sphere-floor/wall/terrain contacts, last substep
  std::int64_t neighbour_entries = 0;    // entries of the neighbour lists (one per pair within r_i + r_j + skin)
  int resorts = 0;                       // grid + neighbour-list rebuilds this step
  int shell_lists = 0;                   // rebuilds of the shell list alone this step (CPU backend)
  bool slept = false;                    // the step did nothing because the sim was asleep
  int sleeping_granules = 0;             // granules asleep in still regions this step (sleep_regions)
  // Wall time of the step's stages, summed over its substeps (s, steady clock): the overlap
  // guard (check_impacts), the pair pass (contacts), the body stage (gather, integrate,
  // rebuild the spheres) and the grid sort + neighbour-list rebuild.
  double guard_seconds = 0, pair_seconds = 0, body_seconds = 0, sort_seconds = 0;
  // GL backend (0 on the CPU): host wall time issuing the substeps' GL commands, and reading
  // the frame's status block back, which waits for the GPU to finish them (s).
  double submit_seconds = 0, readback_seconds = 0;
};

// What a touching contact holds that the positions do not: its tangential spring (Cundall &
// Strack 1979) and its largest overlap (the hysteretic normal spring), by granule and sphere.
// A bed made from another simulation's positions (a patch filled from a settled tile, a
// patch taking over its predecessor's granules) starts its contacts with these instead of
// zero springs, so a bed at rest stays at rest (docs/dem.md "Carried springs").
struct ContactSpring {
  BodyId a;             // a granule
  int sphere_a = 0;     // which of its 4 spheres (0..3)
  BodyId b;             // the other granule, when plane < 0
  int sphere_b = 0;     // (0..3)
  int plane = -1;       // >= 0: a boundary plane instead of b: 0 floor, 1..4 the walls x0, x1, z0, z1, 5 the terrain
  Vec3 xi{};            // m, sim units: the spring of a's sphere against the other (b's against a's is -xi)
  float dmax = 0;       // m, the contact's largest overlap (0 with the linear normal spring)
};

class Simulation {
 public:
  static Result<Simulation> create(const SimulationDef& def);
  Simulation(Simulation&&) noexcept;
  Simulation& operator=(Simulation&&) noexcept;
  ~Simulation();

  // Bodies. Errors name the capacity to raise or the bad field.
  Result<BodyId> add_granule(Vec3 position, Quat orientation = {}, Vec3 velocity = {},
                             Vec3 angular_velocity = {});
  Result<BodyId> add_shell(const ShellDef& shell);
  // Kinematic shells: velocity used by the integrator (m/s, rad/s). Wakes the simulation.
  Status set_kinematic_velocity(BodyId b, Vec3 velocity, Vec3 angular_velocity);

  // ---- control from the terrain manager (manager/terrain_manager.cpp) ----
  // Empties the simulation and takes a new definition (domain, terrain, material, scale)
  // whose capacities do not exceed this one's: a pool slot is reused for the next patch.
  // The capacity-sized arrays keep their memory, and only the entries the last life wrote are
  // set back (writing the whole capacity again took 3.9 ms of a car patch's promotion); the
  // result is the simulation create() makes.
  Status reset(const SimulationDef& def);
  // Sets a body's state (sim units): a shell that follows its Bullet body. Wakes the sim.
  Status set_body_state(BodyId b, Vec3 position, Quat orientation, Vec3 velocity, Vec3 angular_velocity);
  // A disabled body is parked: static, far above the domain, in contact with nothing, until
  // enabled again (then set its state). For shells of bodies that left the patch. Its
  // boundary-plane contacts end when it is parked: enabled again, a plane it touches is a new
  // contact (no spring kept from before).
  Status set_body_enabled(BodyId b, bool enabled);
  // A shell's collision group (ShellDef::group; >= 0). The neighbour list is rebuilt at the
  // next substep when it changes. Errors name the body or the group.
  Status set_body_group(BodyId b, std::int32_t group);
  std::int32_t body_group(BodyId b) const;  // 0 for an id it does not hold

  // Advances dt_frame seconds in substeps of dt_frame / n, n = substeps_for(dt_frame).
  // Refuses (Error naming the parameter) when n would exceed max_substeps, and stops with an
  // Error naming the stage if a NaN appears. The contact store (a CSR neighbour list with one
  // tangential spring per entry) has no per-sphere cap, so nothing can overflow.
  Status step(double dt_frame);
  // Substeps a frame of dt_frame needs (>= 1), or an Error if dt_frame is not > 0.
  Result<int> substeps_for(double dt_frame) const;

  // Overlap guard: the largest speed (m/s, sim units) a body of point effective mass m_pt (kg)
  // may hit something immovable with, f r sqrt(k_n / m_pt) (see max_overlap_fraction);
  // m_pt <= 0 means the lightest dynamic body's (the granule). Infinite when the guard is off.
  double max_impact_speed(double m_pt = 0) const;

  // Stability: contact time (s) of the stiffest/lightest pair and the largest substep (s).
  double contact_time() const;
  double max_substep_dt() const;  // contact_time / accuracy_steps_per_contact
  // Gain of the velocity predictor for a substep of dt s: the contact stage sees the bodies'
  // velocities v + gain (dt a_prev) (1/2: at its own time; less when the damping per substep
  // is large; docs/dem.md "Step size"). The GL backend takes it from its guard simulation.
  bool contact_timing_on(double substep_dt) const;  // SimulationDef::contact_timing at this substep
  double velocity_predictor_gain(double substep_dt) const;

  // Sleep.
  bool asleep() const;
  void wake();
  // Whether granule b sleeps in a still region (SimulationDef::sleep_regions); false for any
  // other body or id.
  bool region_asleep(BodyId b) const;
  // How long granule b has stayed within 0.1 sphere radii of its anchor (s), and the anchor
  // (m, sim units): the still time sleeping regions test. {0, its position} for any other
  // body or without sleep_regions.
  struct StillTime {
    float seconds = 0;
    Vec3 anchor{};
  };
  StillTime still_time(BodyId b) const;
  // Sets it (after set_body_state, which makes a granule awake and not still): a granule
  // handed over from another simulation keeps how long it has been still there. Whether it
  // sleeps is decided at the next step. Nothing to do without sleep_regions. Errors name the
  // field: not a granule, seconds negative or not finite, an anchor not finite.
  Status set_still_time(BodyId b, StillTime still);

  // Contact springs. contact_springs(): every granule-granule and granule-plane contact that
  // touched at the last substep, once (from the side the simulation keeps it), in sorted
  // order; shells' contacts are not included. set_contact_springs(): those contacts start the
  // next step with these springs and largest overlaps, and as touching (no first-substep
  // dashpot); a pair that is not within reach then is left as it is. Errors name the entry
  // and field (a body that is not a granule, a sphere out of 0..3, a plane out of 0..5, a
  // non-finite xi, a dmax negative or not finite) and set nothing.
  std::vector<ContactSpring> contact_springs() const;
  Status set_contact_springs(const std::vector<ContactSpring>& springs);

  // Queries (sim units).
  int body_count() const;
  int particle_count() const;
  int body_particle_count(BodyId b) const;       // spheres of body b; 0 for an id it does not hold
  Vec3 body_position(BodyId b) const;
  Quat body_orientation(BodyId b) const;
  Vec3 body_velocity(BodyId b) const;
  Vec3 body_angular_velocity(BodyId b) const;
  Vec3 body_force(BodyId b) const;   // contact force of the last substep, N (no gravity)
  Vec3 body_torque(BodyId b) const;  // contact torque about the COM, N m
  std::vector<Vec3> particle_positions() const;  // by stable particle id
  double kinetic_energy() const;                 // J, translational + rotational, dynamic bodies
  double potential_energy() const;               // J, gravity (rel. y = 0) + elastic springs
  double max_granule_speed() const;              // m/s, max |v| + |w| d over granules
  const StepStats& last_step() const;
  // Energy ledger (a diagnostic of the CPU backend; the state and its hash do not depend on
  // it): while on, every contact's dissipated work is summed, J (sim units) since the last
  // switch on: by the normal dashpot ((k_n delta - f_n) v_n dt per contact and substep, the
  // clamped force's included) and by friction (-f_t . v dt less the tangential spring's energy
  // change: slip and the tangential damper). The pair pass then runs the scalar law (same
  // results as the AVX2 kernel). kinetic_energy() + potential_energy() (gravity and springs) +
  // these two stays the energy at the switch, up to the integrator's own error and states set
  // from outside (set_body_state).
  void set_energy_ledger(bool on);
  double dissipated_normal() const;    // J
  double dissipated_friction() const;  // J
  double tangential_spring_energy() const;  // J in the tangential springs (pairs and planes; part of potential_energy)
  // J recoverable from the normal springs at the last substep (ledger on only; 1/2 k_n delta^2 each, or
  // the hysteretic spring's f_el^2 / (2 kn2)); potential_energy() counts 1/2 k_n delta^2 whatever the law
  double normal_spring_energy() const;
  // OpenMP threads of the following steps (0 = OpenMP's default); the results do not depend
  // on it. Negative counts are refused.
  Status set_threads(int threads);
  // Sorts the spheres into the grid and builds the neighbour lists now, on this simulation's
  // threads, when its next step would begin with that (granules added, a shell enabled or
  // parked, springs set); else nothing. The step then starts from them: the same results.
  // The next step's stats count it. (The terrain manager, before its patches step side by
  // side one thread each, builds a patch's lists this way on all threads: docs/manager.md
  // "Patches side by side".)
  void build_lists_now();
  // The substep bound N of the following steps (dt_sub <= t_c / N: SimulationDef::
  // accuracy_steps_per_contact), for a frame budget that lowers a live patch's cost; N >= 2,
  // else refused naming the field. The state is kept: the next step takes the new substeps.
  Status set_steps_per_contact(int n);
  std::uint64_t state_hash() const;              // over the fields marked hashed in fields.hpp
  const SimulationDef& def() const;
  const GranuleShape& granule_shape() const;
  double time() const;                           // simulated seconds

  struct Impl;

 private:
  explicit Simulation(std::unique_ptr<Impl> impl);
  // create(); with `reuse`, once `d` is valid, the arrays sized by the capacity are taken
  // from it (their memory kept: reset() fills the same capacity again without allocating).
  static Result<Simulation> make(const SimulationDef& d, Impl* reuse);
  std::unique_ptr<Impl> impl_;
};

}  // namespace sandpatch
