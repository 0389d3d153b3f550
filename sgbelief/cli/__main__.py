from sgbelief.cli import main

raise SystemExit(main())
