from planner import main

raise SystemExit(main())
