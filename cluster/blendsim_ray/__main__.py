from blendsim_ray.cli import main

raise SystemExit(main())
