use bitrock::data::surface::{SurfaceOptions, SurfaceRecord};
use bitrock::eval::surface::*;
use bitrock::laws::Law;
use bitrock::simulate::strings::Chain;
use bitrock::simulate::surface::*;
fn main() {
    let r = SurfaceRecord::read(std::path::Path::new("/tmp/s_m2.csv"), &SurfaceOptions::default()).unwrap();
    let obs = summaries(&r.surface_torque_nm, 1.0);
    let model = SurfaceModel {
        chain: Chain::one_dof(&Default::default()),
        drive: Drive {
            omega_rad_s: r.top_drive_rad_s.clone(),
            ratio: vec![1.0; r.len()],
            period_s: 1.0,
        },
        integration: Integration::default(),
        noise_sd_nm: 200.0,
    };
    let scales: Vec<f64> = std::env::args().skip(1).map(|a| a.parse().unwrap()).collect();
    let mut sc = [1.0; N_SUMMARIES];
    sc.copy_from_slice(&scales);
    let d = Distance {
        observed: obs,
        scales: sc,
    };
    for k in 0..5 {
        for (law, p) in [
            (Law::M2, vec![13000.0, 6500.0, 0.3]),
            (Law::M2, vec![13900.0, 6460.0, 8.4]),
        ] {
            let run = model.simulate(law, &p, NoiseKey::replicate(7, k));
            let s = summaries(&run.surface_torque_nm, 1.0);
            let contrib: Vec<String> = (0..N_SUMMARIES)
                .map(|j| format!("{:.1}", ((s[j] - obs[j]) / sc[j]).powi(2)))
                .collect();
            println!("{:?} rho {:.3} {}", p, d.rho(&s), contrib.join(" "));
        }
    }
}
